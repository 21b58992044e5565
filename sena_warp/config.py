"""Every tunable of the SENA pipeline, in one frozen dataclass, with the range each may take.

Fields are grouped by stage (features, warp, seam, exposure, video, sync, encoding, runtime); in each
group the settings a user changes first come first, the fine tuning after them. Each field carries
the paper's symbol (``docs/method.md`` lists them by stage), its unit and a one-line
meaning; pixel quantities are in input-image pixels unless the name says otherwise. ``RANGES`` below
the class holds every number's range and ``CHOICES`` every text setting's values; a ``Config`` is
checked against them (and the fields that bound each other against each other) when it is made, so
``Config(video_crf=99)`` or ``Config(grid_x="8")`` raise InputError. Where a default departs from the
paper, ``docs/method.md`` says why and ``docs/evaluation.md`` what it buys.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from typing import NamedTuple

from .errors import InputError


@dataclass(frozen=True)
class Config:
    # --- features: keypoints and matches (step 0) ---------------------------------------------
    features: str = "xfeat"  # detector: "xfeat" (ONNX backbone) or "sift"
    xfeat_max_side: int = 1024  # working resolution: long side in px (rounded down to /32)
    xfeat_top_k: int = 4096  # keypoints kept per image, by score = prob x reliability
    # --- features, fine tuning ----------------------------------------------------------------
    xfeat_detection_threshold: float = 0.05  # keypoint probability threshold after NMS
    xfeat_nms_size: int = 5  # NMS window in px (full working resolution)
    min_cossim: float = 0.82  # mutual-NN matches need cosine similarity >= this
    sift_ratio: float = 0.75  # Lowe ratio for the SIFT alternative
    support_neighbours: int = 8  # a match is trusted where enough of this many nearest matches ...
    support_tol_px: float = 3.0  # ... move like it, within this (wrong matches on periodic patterns do not)
    support_min: int = 2  # ... at least this many
    alpha_margin_px: int = 8  # keypoints this close to a fully transparent pixel are dropped (no scene there)
    scale_hint_ratio: float = 4.0  # inputs whose sizes differ more than this: a failed stitch names the ratio

    # --- warp: global affine, overlap, local model, FFD, gate, warp map (steps 1-6) -----------
    ffd_model: str = "fit"  # "fit": lattice fitted to the matches (ours, ffd.py); "blend": the paper's blend of T_j
    gate_model: str = "none"  # "none": D as fitted (ours); "paper": G ramps D in from the source-only border
    lattice_nodes: float = 30.0  # fit: lattice nodes are image diagonal / this apart over the canvas (sweep in evaluation.md)
    min_inliers: int = 12  # fewer inliers than this: no stitch
    ransac_reproj_px: float = 3.0  # RANSAC inlier threshold
    max_canvas_area_ratio: float = 4.0  # refuse a canvas larger than this x (area_src + area_tgt)
    # --- warp, fine tuning: A_glob (step 1) ----------------------------------------------------
    ransac_confidence: float = 0.995  # RANSAC confidence
    ransac_max_iters: int = 2000  # RANSAC iterations (at least)
    global_model_choice: str = "support"  # "support": the model with more matches within fit_match_px; "inliers": more RANSAC inliers (paper)
    global_model_margin: float = 0.02  # support: supports closer than this fraction are a tie, and the inliers decide
    min_overlap_correlation: float = 0.2  # no stitch when the views A_glob aligns correlate less where they overlap
    # --- warp, fine tuning: overlap and cells c_j (step 2) ------------------------------------
    grid_x: int = 6  # G_x: cells across the overlap's bounding box (authors: 2; sweep in evaluation.md)
    grid_y: int = 6  # G_y: cells down the overlap's bounding box
    min_global_det: float = 0.05  # |det A_glob| below this (or det < 0, a flip): implausible model
    min_overlap_area_px: float = 64.0  # overlap polygon smaller than this (px^2): no overlap
    # --- warp, fine tuning: local affines T_j (step 3) ----------------------------------------
    local_match_px: float = 25.0  # matches within this of A_glob feed steps 3-5 (A_glob itself: ransac_reproj_px)
    alpha: float = 0.35  # alpha: sigma_j = alpha * diag(c_j), Gaussian weight of matches
    lambda1: float = 0.005  # lambda_1: ridge pull of T_j toward A_glob (normalised coordinates)
    lambda2: float = 1.0  # lambda_2 > lambda_1: refit strength for unstable cells
    beta: float = 20.0  # beta: conf_j = clip(sum w / (beta * max w), k_min, k_max)
    conf_min: float = 0.2  # k_min
    conf_max: float = 1.5  # k_max
    unstable_min_points: int = 6  # fewer in-cell matches: T_j is unstable
    unstable_rmse_px: float = 5.0  # larger fit RMSE: unstable
    unstable_min_det: float = 0.05  # tau_det: smaller |det|: unstable
    unstable_max_cond: float = 120.0  # larger condition number: unstable
    unstable_max_disp_px: float = 40.0  # larger mean displacement from A_glob (N_g grid): unstable
    instability_grid: int = 5  # N_g: evaluation grid per cell for delta_mean
    w_cond: float = 0.01  # omega_cond in the composite instability score
    w_det: float = 0.5  # omega_det
    tau_det: float = 0.1  # tau_det inside max(0, tau_det - |det|)
    w_delta: float = 0.002  # omega_delta
    # --- warp, fine tuning: FFD field (step 4) -------------------------------------------------
    lambda_bend: float = 1e-6  # lambda_b, fit: thin-plate bending energy against the match residuals (scale-free)
    fit_match_px: float = 50.0  # fit: matches within this of A_glob take part (the IRLS drops wrong ones)
    fit_tukey_px: float = 4.0  # fit: Tukey biweight scale of the iteratively reweighted fit
    fit_iterations: int = 4  # fit: reweighted least-squares solves
    lattice_nx: int = 64  # N_x, blend: FFD lattice nodes across the canvas
    lattice_ny: int = 64  # N_y, blend: FFD lattice nodes down the canvas
    alpha_f: float = 0.35  # alpha_f: sigma_f = alpha_f * mean cell diagonal
    d_max_px: float = 60.0  # d_max: displacement clip
    sigma_l_nodes: float = 0.6  # sigma_l: Gaussian blur on the lattice, in nodes
    # --- warp, fine tuning: seam guard, gate G (step 5) ---------------------------------------
    ramp_min_px: float = 40.0  # b = max(ramp_min_px, ramp_diag_ratio * image diagonal)
    ramp_diag_ratio: float = 0.10  # b as a fraction of the larger image diagonal
    sigma_d_ratio: float = 24.0 / 512.0  # sigma_d: density blur, as a fraction of the image's long side
    gamma_p: float = 1.2  # gamma_p: ramp steepness exponent
    gamma_min: float = 0.9  # gamma_min: gate floor where matches are sparse (paper: 0.30; sweep in evaluation.md)
    sigma_g_px: float = 1.1  # sigma_g: blur of the guarded field
    # --- warp, fine tuning: warp map (step 6) -------------------------------------------------
    forward_tol_px: float = 0.01  # stop inverting M_s once |M_s(u) - s| is below this (source px)
    forward_max_iters: int = 30  # iteration cap of the numeric inversion of M_s (0: its affine start alone)

    # --- seam: adequate zone, keypoint chain, seam path, partition (steps 7-9) ----------------
    seam_model: str = "path"  # "path": cheapest path through anchors (ours, seam_path.py); "paper": straight lines
    transition_px: int = 8  # width of the linear alpha ramp across the seam (paper's code: 24; sweep in evaluation.md)
    seam_blend_ratio: float = 0.08  # seam blend: low-frequency offsets fade over this x image diagonal (0: off)
    border_blend: bool = True  # the seam blend along the target's borders beyond the seam's ends too
    # --- seam, fine tuning: adequate zone and chain (steps 7-8) -------------------------------
    zone_classes: int = 20  # disparity classes of width W / zone_classes
    zone_jump_px: float = 2.0  # v: join a class to the cluster while |d_i - d_(i-1)| <= v
    zone_lambda: float = 1.0  # lambda: weight of |mu_c - mu_g| in w = C / (sigma + lambda dmu + eps)
    zone_eps: float = 1e-3  # epsilon in the cluster score
    flat_min_std: float = 4.0  # drop points whose local grey std is below this (flat regions)
    flat_patch_px: int = 7  # patch side for the flatness and brightness tests
    brightness_max_diff: float = 25.0  # max mean grey difference between warped-source and target patches
    # --- seam, fine tuning: seam path (step 8) ------------------------------------------------
    seam_coarse_px: int = 700  # path: the first search runs on a canvas reduced to this long side
    seam_max_step_px: int = 2  # path: sideways step per canvas row at most (and of the anchor chain)
    seam_step_cost: float = 2.0  # path: cost per pixel of sideways step (grey levels): no near-horizontal runs
    seam_gradient_weight: float = 1.0  # path: weight of the gradient difference beside the colour difference
    seam_edge_weight: float = 0.5  # path: weight of the edge strength (cutting structure costs)
    seam_separation_weight: float = 40.0  # path: cost per row of a seam position between a match's two copies
    seam_separation_rows: int = 3  # path: rows above and below a match that carry that cost
    seam_separation_min_px: float = 2.0  # path: copies closer than this are one point
    seam_separation_max_px: float = 150.0  # path: copies farther apart than this: a wrong match, ignored
    seam_unique_weight: float = 0.0  # path: weight of the structure a seam position would hide
    seam_unique_sigma_px: float = 8.0  # path: smoothing of differences and edge energy for that term
    seam_unique_diff: float = 20.0  # path: views differing by more (grey levels, blurred) show different things
    seam_unique_norm: float = 0.01  # path: hidden structure is summed along a row, per this fraction of its width
    seam_zone_margin: float = 0.5  # path: the search spans the adequate zone widened by this x its width each side
    seam_anchor_px: float = 2.0  # path: anchors lie within this of the reduced-canvas path (reduced px)
    seam_anchor_spacing_px: float = 6.0  # path: anchors at least this far apart down the seam
    seam_refine_px: int = 3  # path: full-resolution band half-width beyond the reduction factor (2 f + this)
    correction_smooth: float = 50.0  # path: smoothing of the anchor residual curve (second differences of nodes 8 rows apart)
    # --- seam, fine tuning: partition and seam blend (step 9) ---------------------------------
    seam_smooth_sigma_px: float = 1.5  # light Gaussian smoothing inside the transition only
    seam_fade_px: float = 64.0  # distance beyond the transition over which the source's anchor correction fades to 0
    seam_blend_strip_px: int = 12  # seam blend: the offsets are measured within this of the seam
    seam_blend_rows: int = 31  # seam blend: and averaged over this many rows
    border_blend_mad_grey: float = 6.0  # seam and border blend: a row or block whose views differ by more (MAD) shows other content
    thin_strip_ratio: float = 0.02  # a view shown only in a strip thinner than this x image diagonal where the other
    # takes over (beyond the other's border) is left out: it shows nothing whole (0: kept, the earlier and the paper's)
    source_past_target: bool = False  # the source shown on the target's side of the seam wherever the target has no
    # pixel (beyond its borders, past the seam's ends: the paper's); False: only as far along each border as the views agree
    past_target_mad_grey: float = 6.0  # there: a block inside the border whose views differ by more (MAD), as they are
    # and smoothed, shows other content
    past_target_sigma_px: float = 2.0  # there: the smoothing of that difference (Gaussian sigma; 0: none)
    seam_blend_gain: bool = True  # seam and border blend: applied as a relative gain (no contrast change);
    # False: per-channel grey levels added (the earlier version)
    seam_blend_colour: bool = True  # seam blend as a gain: per channel, each within 10 % of the grey one
    # (a smooth colour difference of the views: a sky bluer in one); False: one grey value per line
    # --- seam, switch alignment (ours, switch_align.py; no step of the paper) -------------------
    switch_align: bool = False  # align the source to the target at the seam and the borders, cut again (False: the
    # paper's; off by default: it costs 0.7-1.4 s of a 1000x750 stitch, docs/evaluation.md)
    switch_rounds: int = 2  # align and cut again this many times
    # --- seam, switch alignment, fine tuning ----------------------------------------------------
    switch_flow_preset: int = 1  # DIS optical flow preset between the views: 0 ultrafast, 1 fast, 2 medium
    switch_band_px: float = 24.0  # the flow is followed this far from a switch, where both views are defined
    switch_sigma_px: float = 8.0  # and smoothed along the switches by a normalised Gaussian of this sigma
    switch_max_px: float = 80.0  # flow larger than this is not followed (a depth jump the seam must avoid)
    switch_fade_px: float = 48.0  # the correction fades to 0 this far from its switch (smootherstep) at least,
    switch_max_slope: float = 0.25  # and further where it is large: it changes by at most this per px
    switch_cell_px: int = 4  # the correction field is worked out on cells this wide (it is smooth) and upsampled

    # --- exposure: gains of each view (Brown & Lowe 2007; no step of the paper) ----------------
    gain_model: str = "channels"  # "channels": per-channel gains (gains.py); "opencv": cv2's ChannelsCompensator; "none"
    gain_sigma_g: float = 0.5  # sigma_g: std of the gains' prior around 1 (Brown & Lowe, OpenCV: 0.1; sweep in evaluation.md)
    # --- exposure, fine tuning ----------------------------------------------------------------
    gain_sigma_n: float = 10.0  # sigma_N: std of the intensity error (grey levels)
    gain_outlier_fraction: float = 0.2  # the largest differences (misalignment, moving things) left out
    gain_dark_level: float = 5.0  # pixels at or below this in any channel left out (clipped)
    gain_bright_level: float = 250.0  # pixels at or above this left out (saturated)
    gain_knee_ratio: float = 0.9  # gains: above this x white a view's gain line runs straight to white (1: none)
    gain_knee_peak: bool = True  # near white a pixel's channels share its largest's knee (False: each its own)
    gain_stride: int = 2  # every this-th overlap pixel in each direction is used
    gain_min_pixels: int = 500  # fewer agreeing pixels: no compensation
    video_gain_period_s: float = 0.2  # video: gains re-measured on the frames every this many seconds
    video_gain_stride_px: int = 8  # video: the overlap sampled every this many canvas pixels
    video_gain_settle_s: float = 0.3  # video: time constant with which gains follow the measurement
    video_gain_step_grey: float = 0.5  # video: gains alone change the picture by at most this per frame

    # --- video: the rig over time, estimates and the per-frame seam ---------------------------
    video_rig: str = "auto"  # "auto": decided from the first second and watched (video/rig_motion.py); "static":
    # estimated once, moved with a drifting camera; "moving": aligned every frame (video/align.py)
    video_reestimate_s: float = 1.0  # seconds of video between re-estimations of a moving rig
    video_crop: bool = False  # crop the output to the largest rectangle the first estimate covers, for the whole video
    video_start_s: float = 0.0  # the output starts at this time of the left input (s, after the offset); reached by seeking
    video_end_s: float = 0.0  # the output ends before this time of the left input (s); 0: where the inputs end
    video_max_width: int = 0  # the output at most this wide (px; aspect kept, even sides), made by the maps; 0: as stitched
    video_estimate_pairs: int = 5  # first frame pairs tried for the first estimate; most inliers wins
    # --- video, fine tuning: estimates and drift ----------------------------------------------
    video_estimate_spacing: int = 5  # frame pairs between two of those tries
    video_screen_max_side: int = 640  # those tries are ranked by XFeat at this long side at most; the best is estimated at xfeat_max_side
    video_still_background: bool = False  # first estimate: leave out the matches on what moves in front of a still background (video/still_matches.py)
    video_align_in_front: bool = False  # auto: a fixed rig whose first estimate aligned something moving in front of a still background is aligned every frame, its canvas held (off: the room beside it sways with it, docs/evaluation.md)
    video_recur_px: float = 2.0  # first estimate: a match recurs where the pairs beside it have one within this (screening px) at both ends
    video_moving_recur: float = 0.05  # ... a model whose inliers recur at most this share is something that moves, left out
    video_still_recur: float = 0.2  # ... where a model whose inliers recur this share at least (the still background) follows it
    video_moving_models: int = 3  # ... at most this many moving models left out of one pair
    video_estimate_max_side: int = 1920  # an estimate runs on the frames made this small (long side) and is scaled up
    video_rig_moving_share: float = 0.004  # auto: a view drifting this x its width a second or more moves (first second)
    video_rig_switch_share: float = 0.015  # auto: ... and a static rig whose view drifts this much later becomes moving
    video_rig_still_share: float = 0.001  # auto: a moving rig whose views both drift less than this ...
    video_rig_still_s: float = 2.0  # auto: ... for this long becomes static
    video_min_inlier_ratio: float = 0.5  # reject a re-estimate with fewer inliers than this x the first's
    video_max_median_change_px: float = 40.0  # reject a re-estimate moving M_s by more (median over the overlap)
    video_drift_check_s: float = 0.25  # static rig: how often each view is compared with its view at the estimate (0: never)
    video_drift_px: float = 2.0  # static rig: a view's move (input px) beyond this from what the maps follow moves them
    video_drift_speed_px: float = 0.5  # static rig: a drift move is blended in at this many px a frame (faster jolts)
    video_blend_frames: int = 10  # frames over which new maps are blended in linearly (at least): a drift's, a moving rig's new key
    video_edge_home_share: float = 0.75  # an overlap this share of the target across the seam or more (a mostly shared
    # view: a stereo rig, webcams side by side) puts the seam's home at its target-side edge; above 1: the estimate's seam
    video_seam_edge_px: float = 3.0  # ... this far inside the overlap
    video_seam_speed_px: float = 2.0  # the seam moves at most this (or one cell) per frame (a blend lasts long enough), but for jumps
    video_estimate_lookahead_s: float = 1.5  # moving rig, worker: a re-estimate starts on the frame this far ahead of
    # the one composited (those decoded frames are held), so it is ready when the loop reaches its frame; 0: none
    seam_prior_weight: float = 0.5  # moving rig: cost per px (per row) of a new seam's distance from the current one
    video_blank_max_std: float = 2.0  # luma standard deviation below which a frame is blank (e.g. a black start)
    # --- video, fine tuning: a moving rig's alignment every frame (video/align.py) ------------
    video_align_short_px: int = 360  # the planes are aligned made smaller, their short side about this (1 up to 540 rows)
    video_align_points: int = 300  # target corners tracked in the overlap
    video_align_min_share: float = 0.7  # topped up with new corners when fewer than this share remain
    video_align_min_points: int = 20  # fewer points measured: the frame keeps the predicted warp
    video_align_window_px: int = 11  # Lucas-Kanade window (tracks and the warp's residual flow), reduced px (15: 2.3x the CPU, docs/benchmarks.md)
    video_align_lattice_nodes: float = 12.0  # correction lattice: nodes the canvas diagonal / this apart
    video_align_seam_px: float = 32.0  # points within this of the seam (canvas px) are the ones that show ...
    video_align_seam_weight: float = 4.0  # ... and weigh this many times as much; half the new corners are sought there
    video_align_bend: float = 1e-6  # the fit's bending weight (lambda_b of the correction: ffd's, scale-free)
    video_align_tukey_px: float = 3.0  # the fit's Tukey scale (source px): points farther off do not pull
    video_align_prior: float = 1e-4  # the fit's pull towards the predicted lattice (per node, against the mean data term)
    video_align_follow: float = 0.3  # the filter takes this share of a measured change at once (alpha)
    video_align_max_lag_px: float = 1.0  # ... and never lags the measured lattice by more than this
    # --- video, fine tuning: a moving rig's steady canvas (video/steady.py) --------------------
    video_steady_follow: float = 0.1  # the output's path takes this share of the target's camera path's change at once (alpha)
    video_steady_max_px: float = 24.0  # ... and never lags it by more than this (output px; --crop gives it up on every side); 0: off
    # --- video, fine tuning: the per-frame seam -----------------------------------------------
    video_seam_band_ratio: float = 0.05  # band half-width, x the canvas diagonal (room to go round an object)
    video_seam_band_min_px: int = 8  # band half-width at least this
    video_seam_line_step: int = 2  # solved on every this-th line (or every cell-th), interpolated between
    video_seam_frame_cells: int = 360  # the inputs' short side in cells; a cell is round(short side / this) px
    # wide, at least 1 (inputs up to 640x480: 1 px; 720p: 2 px; 1080p: 3 px; 4K: 6 px): the work grows little
    video_seam_noise: float = 6.0  # differences below this (grey levels) are noise, not motion
    video_seam_still_box_px: int = 5  # a line is still where no box this wide changed by video_seam_noise
    video_seam_stay_cost: float = 0.5  # cost per px per line of leaving the last frame's seam
    video_seam_home_cost: float = 0.5  # cost per px per line of leaving the estimate's seam
    video_seam_blocked_cost: float = 100.0  # cost of a band cell outside the overlap
    video_seam_margin: float = 1.0  # a new path must be cheaper by this per line to replace the last
    video_seam_jump_cost: float = 3.0  # it jumps (faster than video_seam_speed_px) to save this per line
    video_seam_motion_cost: float = 40.0  # static rig: cost of a band cell where something is in front of the
    # background (either view off the band's background model by 2 x video_seam_noise): the seam goes round it
    video_seam_background_s: float = 2.0  # static rig: time constant of the band's background model (seconds)
    video_seam_foreground_learn: float = 0.1  # static rig: a view's model learns this x as fast where the view is
    # off it (someone standing still stays in front for ten time constants, not one)
    video_seam_spread_learn: float = 0.5  # static rig: a view's spread (a cell's usual change a frame) learns this x
    # as fast where the view is off (a textured object walking past changes its cells every frame; 1: as elsewhere)
    video_seam_object_cost: float = 1000.0  # static rig: cost of a band cell on an object's two copies or between
    # them (video/frame_objects.py): the seam keeps off them and shows the object whole from one view

    # --- sync: --offset auto, from audio or motion (video/sync.py) ----------------------------
    sync_max_lag_s: float = 10.0  # largest offset searched, either sign (seconds)
    # --- sync, fine tuning --------------------------------------------------------------------
    sync_min_overlap_s: float = 3.0  # offsets where the signals share less than this (seconds) are not searched
    sync_min_overlap: float = 0.5  # ... nor those where they share less than this x the shorter one
    sync_min_confidence: float = 0.4  # refuse a peak going less of the way from its runner-up to a perfect match
    sync_audio_rate_hz: int = 8000  # audio is resampled to mono at this rate before correlating
    sync_audio_span_s: float = 30.0  # audio correlated: the first this many seconds of each input
    sync_audio_min_rms: float = 1e-4  # quieter audio (full scale 1) is silence: refused
    sync_audio_min_peak: float = 0.3  # refuse a lower waveform correlation: the microphones hear different sounds
    sync_audio_exclusion_s: float = 0.05  # the runner-up is sought at least this far from the peak (past its ringing)
    sync_motion_span_s: float = 30.0  # video correlated: the first this many seconds of each input
    sync_motion_side_px: int = 128  # frames are area-downscaled to this long side before differencing
    sync_motion_median_frames: int = 3  # median filter of the frame-difference energy: one-frame spikes are no motion
    sync_motion_min_spread: float = 0.1  # robust std of that energy (grey levels) below this: a static scene, refused
    sync_motion_min_peak: float = 0.8  # refuse a lower energy correlation: the two views do not see the same motion

    # --- encoding: the output video ------------------------------------------------------------
    video_codec: str = "libx264"  # encoder: H.264 "libx264" or "h264_nvenc", HEVC "libx265" or "hevc_nvenc" (NVENC falls back to software)
    video_crf: int = 20  # constant rate factor (libx264/libx265 crf, nvenc cq): lower = better, larger files
    video_bitrate_kbps: int = 0  # average bit rate (kbit/s) instead of the constant quality video_crf; 0: constant quality
    video_maxrate_kbps: int = 0  # peak bit rate (kbit/s; a buffer of 2 s of it) capping either rate control; 0: none
    video_preset: str = "veryfast"  # libx264 speed/size preset
    video_audio: str = "left"  # audio copied into the output: "left", "right" or "none"
    video_encoder_thread_type: str = "slice"  # libx264 threads: "slice" (parts of one frame) or "frame" (frames in flight)

    # --- runtime: device, threads, memory ------------------------------------------------------
    device: str = "auto"  # Warp device: "auto", "cpu" or "cuda"
    cpu_threads: int = 0  # threads of the Warp CPU row bands, onnxruntime and the video codecs; 0 = one per core
    max_input_megapixels: float = 100.0  # refuse a larger input, from its header before decoding (memory; README)
    # --- runtime, fine tuning -----------------------------------------------------------------
    video_queue_frames: int = 8  # decoded frames buffered per input between decoder thread and loop
    video_opencv_threads: int = 1  # OpenCV's threads while a video's frames are stitched (its calls there are small:
    # waking and spinning a pool cost more CPU than they save); 0 = OpenCV's own choice
    video_estimate_workers: int = 1  # moving rig: re-estimates run on this many threads off the frame loop (0: on it)
    video_estimate_lookahead_mib: int = 512  # the most a re-estimate's look-ahead holds of decoded frames (1080p: 45
    # pairs, 4K: 21); also the most the first estimate's pairs may hold for the loop (more: it decodes its own)

    def __post_init__(self) -> None:
        for name, kind in field_types().items():
            value = getattr(self, name)
            if isinstance(value, bool) or type(value) is kind:
                continue
            if kind is float and isinstance(value, numbers.Real):
                object.__setattr__(self, name, float(value))  # Config(alpha=1) is alpha = 1.0; numpy numbers too
            elif kind is int and isinstance(value, numbers.Integral):
                object.__setattr__(self, name, int(value))
        problem = config_problem(self)
        if problem is not None:
            raise InputError(f"Config: {problem}")

    def replace(self, **changes) -> "Config":
        """A copy with some fields changed (unknown names raise TypeError, bad values InputError)."""
        return dataclasses.replace(self, **changes)


# The values a text setting may take; the CLI's choices and the settings-file checks read them here.
CHOICES: dict[str, tuple[str, ...]] = {
    "features": ("xfeat", "sift"),
    "video_codec": ("libx264", "libx265", "h264_nvenc", "hevc_nvenc"),
    "video_preset": ("ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow", "slower",
                     "veryslow", "placebo"),
    "video_audio": ("left", "right", "none"),
    "video_encoder_thread_type": ("slice", "frame"),
    "video_rig": ("auto", "static", "moving"),
    "ffd_model": ("fit", "blend"),
    "gate_model": ("none", "paper"),
    "seam_model": ("path", "paper"),
    "gain_model": ("channels", "opencv", "none"),
    "global_model_choice": ("inliers", "support"),
    "device": ("auto", "cpu", "cuda"),
}
OFFSET_AUTO = "auto"  # --offset, or a batch job's offset, that is estimated from the inputs (video/sync.py)


class Range(NamedTuple):
    """The values a number setting may take: ``low`` to ``high``, both included unless ``above``
    (then ``low`` itself is not). Upper bounds keep a run's memory and time bounded."""

    low: float
    high: float
    above: bool = False

    def holds(self, value: float) -> bool:
        return (value > self.low if self.above else value >= self.low) and value <= self.high

    def __str__(self) -> str:
        return f"{'(' if self.above else '['}{_number(self.low)}, {_number(self.high)}]"  # ( : low itself is not allowed


def _number(value: float) -> str:
    """``value`` as a user typed it: whole numbers in full (1000000, not 1e+06)."""
    return str(int(value)) if float(value).is_integer() else f"{value:g}"


def _above(low: float, high: float) -> Range:
    return Range(low, high, above=True)


# Every number setting's range, grouped as the class is (a test checks that none is missing).
RANGES: dict[str, Range] = {
    # features
    "xfeat_max_side": Range(32, 4096), "xfeat_top_k": Range(16, 16384), "xfeat_detection_threshold": Range(0, 1),
    "xfeat_nms_size": Range(1, 63), "min_cossim": Range(0, 1), "sift_ratio": _above(0, 1),
    "support_neighbours": Range(1, 64), "support_tol_px": _above(0, 1000), "support_min": Range(1, 64),
    "alpha_margin_px": Range(0, 1000), "scale_hint_ratio": Range(1, 1000),
    # warp
    "lattice_nodes": Range(2, 200), "min_inliers": Range(3, 10000), "ransac_reproj_px": _above(0, 1000),
    "max_canvas_area_ratio": Range(1, 100), "ransac_confidence": _above(0, 1), "ransac_max_iters": Range(1, 100000),
    "global_model_margin": Range(0, 1), "min_overlap_correlation": Range(0, 1), "grid_x": Range(1, 64), "grid_y": Range(1, 64), "min_global_det": Range(0, 1),
    "min_overlap_area_px": Range(0, 1e9), "local_match_px": _above(0, 10000), "alpha": _above(0, 100),
    "lambda1": Range(0, 1e12), "lambda2": _above(0, 1e12), "beta": _above(0, 10000), "conf_min": _above(0, 100),
    "conf_max": _above(0, 100), "unstable_min_points": Range(0, 10000), "unstable_rmse_px": _above(0, 10000),
    "unstable_min_det": Range(0, 100), "unstable_max_cond": _above(0, 1e12), "unstable_max_disp_px": Range(0, 10000),
    "instability_grid": Range(1, 64), "w_cond": Range(0, 1000), "w_det": Range(0, 1000), "tau_det": Range(0, 100),
    "w_delta": Range(0, 1000), "lambda_bend": Range(0, 1000), "fit_match_px": _above(0, 10000),
    "fit_tukey_px": _above(0, 1000), "fit_iterations": Range(1, 100), "lattice_nx": Range(2, 512),
    "lattice_ny": Range(2, 512), "alpha_f": _above(0, 100), "d_max_px": _above(0, 10000), "sigma_l_nodes": Range(0, 16),
    "ramp_min_px": Range(0, 10000), "ramp_diag_ratio": Range(0, 1), "sigma_d_ratio": _above(0, 1),
    "gamma_p": _above(0, 100), "gamma_min": Range(0, 1), "sigma_g_px": Range(0, 64), "forward_tol_px": _above(0, 10),
    "forward_max_iters": Range(0, 1000),
    # seam
    "transition_px": Range(1, 512), "seam_blend_ratio": Range(0, 1), "zone_classes": Range(1, 1000),
    "zone_jump_px": Range(0, 10000), "zone_lambda": Range(0, 1000), "zone_eps": _above(0, 1000),
    "flat_min_std": Range(0, 255), "flat_patch_px": Range(1, 64), "brightness_max_diff": Range(0, 255),
    "seam_coarse_px": Range(64, 8192), "seam_max_step_px": Range(1, 64), "seam_step_cost": Range(0, 10000),
    "seam_gradient_weight": Range(0, 1000), "seam_edge_weight": Range(0, 1000), "seam_separation_weight": Range(0, 1e6),
    "seam_separation_rows": Range(1, 64), "seam_separation_min_px": _above(0, 10000),
    "seam_separation_max_px": _above(0, 10000), "seam_unique_weight": Range(0, 1000),
    "seam_unique_sigma_px": _above(0, 256), "seam_unique_diff": _above(0, 255), "seam_unique_norm": _above(0, 1),
    "seam_zone_margin": Range(0, 100), "seam_anchor_px": _above(0, 1000), "seam_anchor_spacing_px": _above(0, 10000),
    "seam_refine_px": Range(0, 256), "correction_smooth": Range(0, 1e9), "seam_smooth_sigma_px": Range(0, 64),
    "seam_fade_px": Range(0, 10000), "seam_blend_strip_px": Range(1, 1024), "seam_blend_rows": Range(1, 1023),
    "border_blend_mad_grey": _above(0, 255), "past_target_mad_grey": _above(0, 255), "past_target_sigma_px": Range(0, 64),
    "thin_strip_ratio": Range(0, 1), "switch_rounds": Range(0, 8),
    "switch_flow_preset": Range(0, 2), "switch_band_px": _above(0, 1024), "switch_sigma_px": _above(0, 256),
    "switch_max_px": _above(0, 10000), "switch_fade_px": Range(0, 10000), "switch_max_slope": _above(0, 10),
    "switch_cell_px": Range(1, 64),
    # exposure
    "gain_sigma_g": _above(0, 100), "gain_sigma_n": _above(0, 255), "gain_outlier_fraction": Range(0, 0.99),
    "gain_dark_level": Range(0, 254), "gain_bright_level": _above(0, 255), "gain_knee_ratio": _above(0, 1),
    "gain_stride": Range(1, 64), "gain_min_pixels": Range(1, 10_000_000), "video_gain_period_s": _above(0, 3600),
    "video_gain_stride_px": Range(1, 256), "video_gain_settle_s": Range(0, 3600), "video_gain_step_grey": _above(0, 255),
    # video
    "video_reestimate_s": _above(0, 3600), "video_estimate_pairs": Range(1, 100), "video_estimate_spacing": Range(1, 1000),
    "video_recur_px": _above(0, 100), "video_moving_recur": Range(0, 1), "video_still_recur": Range(0, 1),
    "video_moving_models": Range(0, 20),
    "video_screen_max_side": Range(32, 4096), "video_estimate_max_side": Range(64, 8192),
    "video_min_inlier_ratio": Range(0, 1), "video_max_median_change_px": Range(0, 10000),
    "video_drift_check_s": Range(0, 3600), "video_drift_px": _above(0, 10000), "video_drift_speed_px": _above(0, 10000),
    "video_blend_frames": Range(0, 10000), "video_seam_speed_px": _above(0, 10000), "video_edge_home_share": Range(0, 2),
    "video_seam_edge_px": Range(0, 10000), "video_rig_moving_share": _above(0, 1),
    "video_rig_switch_share": _above(0, 1), "video_rig_still_share": _above(0, 1), "video_rig_still_s": _above(0, 3600),
    "video_align_short_px": Range(32, 4096), "video_align_points": Range(1, 10000), "video_align_min_share": Range(0, 1),
    "video_align_min_points": Range(3, 10000), "video_align_window_px": Range(3, 99),
    "video_align_lattice_nodes": _above(1, 200), "video_align_seam_px": Range(0, 10000),
    "video_align_seam_weight": Range(1, 1000), "video_align_bend": Range(0, 1000), "video_align_tukey_px": _above(0, 1000),
    "video_align_prior": Range(0, 1000), "video_align_follow": _above(0, 1), "video_align_max_lag_px": _above(0, 10000),
    "video_steady_follow": _above(0, 1), "video_steady_max_px": Range(0, 10000),
    "video_estimate_lookahead_s": Range(0, 60), "seam_prior_weight": Range(0, 1000), "video_blank_max_std": Range(0, 255),
    "video_seam_band_ratio": _above(0, 1), "video_seam_band_min_px": Range(1, 4096), "video_seam_line_step": Range(1, 64),
    "video_seam_frame_cells": Range(8, 8192), "video_seam_noise": Range(0, 255), "video_seam_still_box_px": Range(1, 64),
    "video_seam_stay_cost": Range(0, 10000), "video_seam_home_cost": Range(0, 10000),
    "video_seam_blocked_cost": _above(0, 1e6), "video_seam_margin": Range(0, 10000),
    "video_seam_jump_cost": Range(0, 10000), "video_seam_motion_cost": Range(0, 1e6),
    "video_seam_background_s": _above(0, 3600), "video_seam_foreground_learn": Range(0, 1), "video_seam_spread_learn": Range(0, 1),
    "video_seam_object_cost": Range(0, 1e6), "video_start_s": Range(0, 1e6), "video_end_s": Range(0, 1e6),
    "video_max_width": Range(0, 16384),
    # sync
    "sync_max_lag_s": _above(0, 3600), "sync_min_overlap_s": _above(0, 3600), "sync_min_overlap": _above(0, 1),
    "sync_min_confidence": Range(0, 1), "sync_audio_rate_hz": Range(100, 48000), "sync_audio_span_s": _above(0, 600),
    "sync_audio_min_rms": Range(0, 1), "sync_audio_min_peak": Range(0, 1), "sync_audio_exclusion_s": Range(0, 10),
    "sync_motion_span_s": _above(0, 600), "sync_motion_side_px": Range(16, 1024),
    "sync_motion_median_frames": Range(1, 99), "sync_motion_min_spread": Range(0, 255),
    "sync_motion_min_peak": Range(0, 1),
    # encoding
    "video_crf": Range(0, 51), "video_bitrate_kbps": Range(0, 1_000_000), "video_maxrate_kbps": Range(0, 1_000_000),
    # runtime: more threads than cores only costs memory (a thread's stack; onnxruntime stalls under a memory limit)
    "cpu_threads": Range(0, 256), "max_input_megapixels": _above(0, 10000), "video_queue_frames": Range(1, 64),
    "video_estimate_workers": Range(0, 16), "video_opencv_threads": Range(0, 256), "video_estimate_lookahead_mib": Range(1, 65536),
}

# Fields that bound each other: (field, relation, other field, why), checked after each field's own range.
BOUNDS_BETWEEN = (
    ("conf_min", "<=", "conf_max", "k_min <= k_max"),
    ("lambda1", "<", "lambda2", "the refit is stronger"),
    ("support_min", "<=", "support_neighbours", "of that many neighbours"),
    ("gain_dark_level", "<", "gain_bright_level", "some levels are left to measure"),
    ("seam_separation_min_px", "<", "seam_separation_max_px", "some copies are far enough apart"),
    ("sync_min_overlap_s", "<=", "sync_audio_span_s", "offsets are searched within the audio correlated"),
    ("sync_min_overlap_s", "<=", "sync_motion_span_s", "offsets are searched within the video correlated"),
)
_RELATIONS = {"<": (lambda a, b: a < b), "<=": (lambda a, b: a <= b)}
KIND_WORDS = {int: "a whole number", float: "a number", str: "text", bool: "true or false"}


@functools.lru_cache(maxsize=1)
def field_types() -> Mapping[str, type]:
    """Field name -> its Python type (``int``, ``float``, ``str`` or ``bool``), read-only; worked out once
    (a Config is checked each time one is made)."""
    hints = typing.get_type_hints(Config)
    return types.MappingProxyType({f.name: hints[f.name] for f in dataclasses.fields(Config)})


def shown(value) -> str:
    """``value`` as a settings file writes it (TOML): text quoted, true / false."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return repr(value) if isinstance(value, (int, float)) else f"{value!r} ({type(value).__name__})"


def value_problem(name: str, value) -> str | None:
    """What is wrong with ``value`` for the field ``name`` (type, choice, finite, range), or None.

    An int is accepted for a float field (TOML ``2`` for ``2.0``); a bool is not a number."""
    kind = field_types()[name]
    is_int = isinstance(value, numbers.Integral) and not isinstance(value, bool)
    fits = (isinstance(value, bool) if kind is bool else isinstance(value, str) if kind is str
            else is_int if kind is int else is_int or isinstance(value, numbers.Real) and not isinstance(value, bool))
    if not fits:
        return f"{name} = {shown(value)} is not {KIND_WORDS[kind]} (default: {shown(getattr(Config, name))})"
    if kind is str:
        allowed = CHOICES.get(name)
        return None if allowed is None or value in allowed else f"{name} = {shown(value)} is not one of {', '.join(allowed)}"
    if kind is bool:
        return None
    if not math.isfinite(value):
        return f"{name} = {value} must be a finite number"
    allowed_range = RANGES[name]
    if not allowed_range.holds(value):
        return f"{name} = {value} is out of range {allowed_range}"
    return None


def config_problem(cfg: Config) -> str | None:
    """The first problem of ``cfg``: a field's (:func:`value_problem`), then two fields that disagree."""
    for name in field_types():
        problem = value_problem(name, getattr(cfg, name))
        if problem is not None:
            return problem
    for name, relation, other, why in BOUNDS_BETWEEN:
        value, bound = getattr(cfg, name), getattr(cfg, other)
        if not _RELATIONS[relation](value, bound):
            return f"{name} = {value} must be {relation} {other} = {bound} ({why})"
    return None


def require_config(cfg, where: str) -> Config:
    """``cfg`` when it is a :class:`Config` (a public function's argument check), else InputError."""
    if not isinstance(cfg, Config):
        raise InputError(f"{where}: cfg must be a Config (sena_warp.config.Config(...)), got {type(cfg).__name__}")
    return cfg


def is_seconds(value) -> bool:
    """Whether ``value`` is a finite real number (not a bool): a time in seconds such as an offset."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)
