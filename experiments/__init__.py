"""One folder per study, and the railfmu command line."""
