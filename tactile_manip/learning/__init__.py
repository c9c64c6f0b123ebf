"""Training, export and dataset tooling for the SuperMag CVAE. The only package that imports torch."""
