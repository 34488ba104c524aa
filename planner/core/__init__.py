"""Run the method: steps, the pipeline and its runner, sessions, results, caches, paths, TOML reading, forked workers, text made
safe for markdown and HTML."""
