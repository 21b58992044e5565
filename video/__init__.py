"""Paired-video stitching with PyAV (installed as ``sena_warp.video``)."""
