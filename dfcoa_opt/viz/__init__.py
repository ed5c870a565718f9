"""Pictures and viewer files of runs: figures, animations and MCAP logs, read from run logs."""
