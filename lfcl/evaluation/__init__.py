"""`lfcl evaluate`: methods scored against a simulated capture's ground truth; metrics and plots."""
