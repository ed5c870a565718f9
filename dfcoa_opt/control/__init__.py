"""Controller and safety-filter interfaces, adapters, registry and built-in controllers."""
