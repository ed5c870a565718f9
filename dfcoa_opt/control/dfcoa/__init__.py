"""``dfcoa``: the DFCOA controller of paper 000 and its parts.

- :mod:`~dfcoa_opt.control.dfcoa.controller`: the registered controller (the parts composed);
- :mod:`~dfcoa_opt.control.dfcoa.formation_law`: the formation tracking law (eq 15-28);
- :mod:`~dfcoa_opt.control.dfcoa.histogram`: the improved VFH* histogram stages (Algorithm 1);
- :mod:`~dfcoa_opt.control.dfcoa.vfh_star`: the VFH* pipeline and the safety layer (§4.5.3).
"""

from dfcoa_opt.control.dfcoa.controller import DFCOA

__all__ = ["DFCOA"]
