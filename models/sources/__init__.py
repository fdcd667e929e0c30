"""Generic components of a system: a step source, sensor noise, a measured-data table."""
