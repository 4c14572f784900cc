"""Data shipped with lfcl (fitted coefficients): see the README of each file's fitting script."""
