"""The Poisson-Gaussian noise model of a lenslet raw, from its NoiseProfile or estimated from it."""
