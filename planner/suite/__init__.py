"""Task suites: many tasks generated from one suite file, run through the pipeline on local workers or Ray, and reported.

`spec.py` reads suite files, `generate.py` makes their tasks, `job.py` runs one task (in any worker), `executors.py`
runs jobs on local processes or Ray, `run.py` drives a suite into its folder (resumable), `summary.py` totals it and
`report.py` draws its HTML report.
"""
