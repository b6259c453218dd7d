"""FMU export (FMI 2.0 Model Exchange and Co-Simulation) of compiled models."""
