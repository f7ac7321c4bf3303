"""Many runs: campaigns, where runs execute (serial, process pool, Dask), the results store and the code fingerprint."""
