"""Run the method: steps and their runner, sessions, results, caches, paths, TOML reading, forked workers, text made
safe for markdown and HTML."""
