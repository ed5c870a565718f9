"""Policies as controllers: a network in a data file (``policy:PATH``), or a Python callable.

- :mod:`~dfcoa_opt.control.policy.controller`: the controllers;
- :mod:`~dfcoa_opt.control.policy.file`: the policy file format (JSON spec + ``.npz``).
"""

from dfcoa_opt.control.policy.controller import (
    FilePolicy,
    PolicyController,
    callable_policy_class,
    file_policy_class,
)
from dfcoa_opt.control.policy.file import (
    ACTIVATIONS,
    FORMAT,
    PREFIX,
    VERSION,
    LoadedPolicy,
    PolicySpec,
    load_policy,
    policy_digest,
)

__all__ = ["ACTIVATIONS", "FORMAT", "PREFIX", "VERSION", "FilePolicy", "LoadedPolicy",
           "PolicyController", "PolicySpec", "callable_policy_class", "file_policy_class",
           "load_policy", "policy_digest"]
