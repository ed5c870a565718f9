"""The results of a sweep: the store of rows and logs, the code fingerprint, log files."""
