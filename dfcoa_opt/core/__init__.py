"""The bottom layer: errors, typed parameters, geometry, the registry class, runtime pins.

Every other room of the package may import it; it imports none of them. It
stays empty of imports: :mod:`dfcoa_opt` runs
:func:`dfcoa_opt.core.runtime.dispatch.pin` before anything imports numpy.
"""
