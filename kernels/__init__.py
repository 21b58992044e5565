"""NVIDIA Warp kernels for SENA's per-pixel work (installed as ``sena_warp.kernels``).

They run on ``cuda`` when a GPU is present and on Warp's ``cpu`` device otherwise; on CPU a launch
is split into row bands launched from a small thread pool so every core is used.

Every kernel module is built forward only (``enable_backward`` False): nothing here is differentiated,
and Warp's adjoint code took 60 % of a first run's compile (34-41 s against 13-14 s for all the
modules on the project's 2-core machine). The option is set per module, not in ``warp.config``, so a
program that uses Warp's autodiff beside this package keeps it.
"""
