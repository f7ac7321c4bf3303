"""The results store: what a store of runs promises (`base`), a results folder on disk
(`folder`: `ResultStore`, its SQLite `index`, `runfiles`, rows `committing` in batches,
`repair`, `export`) and in memory (`memory`), a run written where it executes
(`writing`), a stored run as handed out (`records`) and every signal of one
re-simulated on request (`resimulate`); `errors` names what a folder cannot do.

This package imports nothing: a worker writing its run loads only `writing` and what it
needs, so editing the folder's reader leaves stored runs valid (the code fingerprint
covers what a run loads, `validation.batch.fingerprint`).
"""
