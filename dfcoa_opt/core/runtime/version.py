"""The toolkit's version, which every run log records (``meta["version"]``)."""

__version__ = "0.1.0"
