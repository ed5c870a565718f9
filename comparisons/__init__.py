"""Controllers from the companion papers (001, 002, 004) and beyond.

One package per method, named by its controller id (``orca``, ``cbf``,
``lf_vo``, ``nmpc``, ``virtual_spring``, ``reshape``); a module where one file is the whole
method (``consensus``). ``constraints`` holds what the constraint-based
methods share: the distance geometry of ``cbf`` and ``nmpc`` and the
``qpsolvers`` plumbing of ``orca`` and ``cbf``. Importing a method's
package registers its controllers (:mod:`dfcoa_opt.control.registry`).

The module paths of release 0.1 (``comparisons.lf_vo_core``, ...) still import,
with a :class:`DeprecationWarning` naming the new path, until 0.3.
"""

from dfcoa_opt.core.moved import keep_old_paths

#: Module paths of release 0.1 -> their homes since 0.2.
MOVED = {
    "comparisons.cbf_qp": "comparisons.cbf.qp",
    "comparisons.lf_vo_core": "comparisons.lf_vo.equations",
    "comparisons.lf_vo_kernel": "comparisons.lf_vo.kernel",
    "comparisons.nmpc_problem": "comparisons.nmpc.problem",
    "comparisons.nmpc_geometry": "comparisons.nmpc.geometry",
    "comparisons.virtual_spring_core": "comparisons.virtual_spring.equations",
    "comparisons.virtual_spring_conflict": "comparisons.virtual_spring.conflict",
    "comparisons.distance_constraints": "comparisons.constraints.distance",
    "comparisons.orca.ivo_disc": "comparisons.orca.ivo.discs",
    "comparisons.orca.ellipse": "comparisons.orca.ivo.ellipse",
    "comparisons.orca.qp_backend": "comparisons.constraints.solvers",
    "comparisons.reshape.route_mode": "comparisons.reshape.central",
}

keep_old_paths(MOVED, removal="0.3")
