"""What the process runs on: the SIMD cap, the numba cache, kernel threads, the version.

Empty of imports, like :mod:`dfcoa_opt.core`: the SIMD cap must be pinned
before numpy loads.
"""
