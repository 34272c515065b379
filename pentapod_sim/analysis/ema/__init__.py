"""Experimental modal analysis of measured FRFs: pLSCF poles, LSFD residues, tables, plots."""
