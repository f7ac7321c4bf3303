"""Many runs: campaigns, where runs execute (serial, process pool, Dask), the code fingerprint, and the results store (`validation.batch.store`)."""
