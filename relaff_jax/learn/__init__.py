"""Learning: the paper's random forests, the bootstrapping protocol, sweeps and their analysis."""
