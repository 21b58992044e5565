"""NVIDIA Warp kernels for SENA's per-pixel work (installed as ``sena_warp.kernels``).

They run on ``cuda`` when a GPU is present and on Warp's ``cpu`` device otherwise; on CPU a launch
is split into row bands launched from a small thread pool so every core is used.

Every kernel module is built forward only (``enable_backward`` False): nothing here is differentiated,
and Warp's adjoint code took 60 % of a first run's compile (34-41 s against 13-14 s for all the
modules on the project's 2-core machine). CPU kernels are built for any x86-64 CPU, not with Warp's
default ``-march=native`` (no slower here: ``benchmarks/cpu_portable.py``), so the build in ``built/``
(``tools/ship_kernels.py``) runs on every machine and a first run need not compile. The options are set
per module (:data:`MODULE_OPTIONS`), not in ``warp.config``, so a program that uses Warp beside this
package keeps its own.
"""

MODULE_OPTIONS = {"enable_backward": False, "cpu_compiler_flags": ""}  # every kernel module's build options
