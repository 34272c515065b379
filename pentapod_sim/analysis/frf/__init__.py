"""FRF estimation from recorded runs: Welch H1/H2, periodic, stepped sine; peaks, export, plots."""
