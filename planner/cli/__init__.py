"""The `regrasp` command line's headless side: the parser's parts (`arguments.py`), one module per group of commands
(`plan.py`: check, plan, params; `suite.py`; `offline.py`: roadmap, grasps; `bench_commands.py` over the benchmarks of
`bench.py`), progress bars (`progress.py`) and the entry that runs a command (`main.py`)."""
