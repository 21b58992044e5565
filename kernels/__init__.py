"""NVIDIA Warp kernels for SENA's per-pixel work (installed as ``sena_warp.kernels``).

They run on ``cuda`` when a GPU is present and on Warp's ``cpu`` device otherwise; on CPU a launch
is split into row bands launched from a small thread pool so every core is used.
"""
