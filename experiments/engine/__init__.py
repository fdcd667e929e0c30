"""The run engine, under the studies: runner, observer bank, recorder, study (Monte Carlo on
Dask), study protocol, plots and the command line. It knows no study by name."""
