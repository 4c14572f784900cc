"""The pipeline as objects (Decode, Grid, Demosaic, Outputs) and the recipes that configure it."""
