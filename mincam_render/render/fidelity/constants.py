"""Bounds, pilot sample counts and shares of the fidelity planner (one place to tune them)."""

from mincam_render.render.differential import DifferenceSeeds

#: Probe frames rendered for the measurements.
PROBE_FRAMES = 3
#: Samples per texel of the pilot renders.
PILOT_SPP = 4
#: spp chosen automatically stays in [1, MAX_AUTO_SPP].
MAX_AUTO_SPP = 1024
#: Reference renders for the spp check use this many times the chosen spp.
REFERENCE_SPP_FACTOR = 8
#: Cap on the reference's spp (keeps planning a noisy scene to minutes).
MAX_REFERENCE_SPP = 4096
#: The reference of a differential plan gets the spp whose predicted noise is this
#: share of the target error (its noise is subtracted in quadrature from the check).
REFERENCE_NOISE_SHARE = 0.2
#: Path depths tried, shallowest first, against the deep reference.
CANDIDATE_DEPTHS = (2, 3, 4, 6, 8, 12)
#: Path depth of the reference when the scene's integrator is unbounded (-1).
DEEP_REFERENCE_DEPTH = 16
#: A shared render is chosen when parallax changes measurements by less than this
#: share of the target error (or by less than ``parallax_fraction`` texels).
SHARED_ERROR_SHARE = 0.5
#: spp of FULL fidelity when --spp is not given.
FULL_SPP = 64
#: Rays per side of the grid cast to estimate scene depth.
DEPTH_GRID = 16
#: Cap on the background's spp.
MAX_BACKGROUND_SPP = 16384
#: spp of the two renders whose difference gives the noise of ``X - C``: more than
#: PILOT_SPP, because the rare paths that find the sunlit floor make its noise
#: heavy-tailed and a small pilot underestimates it.
DIFFERENCE_PILOT_SPP = 16
#: Times the differential spp are raised when the check against the reference
#: misses the target (each by the squared ratio of the error found to the planned).
MAX_SPP_RAISES = 2
#: spp of the two renders of each probe's background whose difference gives the
#: backgrounds' noise (see _background_noise).
BACKGROUND_PILOT_SPP = 64
#: spp of the frame render that relative errors of ``X - C`` are taken against.
DIFFERENCE_BASE_SPP = 32
#: Differential settings are planned for this share of the target error; the rest
#: covers the uncertainty of figures measured on a few probe frames.
PLAN_ERROR_SHARE = 0.9
#: spp of the renders that measure the parallax error of one ``X - C`` for all
#: detectors (a difference of noise levels: it needs noise well below the bound).
SHARED_DIFFERENCE_SPP = 128
#: spp cap of the renders that measure the daylight interpolation of backgrounds
#: (common random numbers: the drift's change, not noise, dominates).
INTERPOLATION_SPP = 256
#: Frames of the planning episode the label signal is rendered on (spread over it):
#: its spread over frames needs more states than the probes' three.
SIGNAL_FRAMES = 24
#: spp of each of the label signal's two estimates (their covariance has no noise
#: term, so a few samples suffice).
SIGNAL_SPP = 16
#: Box pixel (texels per side) whose signal-relative error is reported beside the
#: random masks': a single texel, the finest pixel the rendered texels allow.
FINEST_BOX_TEXELS = 1
#: Target relative to the label signal of a family without one of its own (its
#: noise as large as its signal: about 1 % of the total in the indoor tasks).
DEFAULT_SIGNAL_TARGET_ERROR = 1.0
#: Seeds of ``X - C`` when the request leaves them open (chosen by measurement:
#: benchmarks/results/task_fidelity.json).
DIFFERENCE_SEEDS = DifferenceSeeds.WINDOW
