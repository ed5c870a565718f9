"""Global planning for the virtual leader and path tracking."""
