"""ROS-free analysis of recorded bags: loading, FRF estimation, peaks, UFF58/CSV, plots."""
