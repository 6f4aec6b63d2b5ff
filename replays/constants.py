"""Dataset facts of ETH/UCY and the benchmark protocols (0.4 s steps)."""

from __future__ import annotations

from typing import Final

STEP_S: Final[float] = 0.4  # one annotated frame = one env step [s]
FRAME_STRIDE: Final[int] = 10  # frame ids of consecutive annotated frames differ by 10
T_OBS: Final[int] = 8  # observed steps (3.2 s) of the standard protocol
T_OBS_MOMENTARY: Final[int] = 2  # observed steps (0.8 s) of the momentary-observation task
T_PRED: Final[int] = 12  # predicted steps (4.8 s)
MIN_AGENTS_PER_WINDOW: Final[int] = 2  # Social-GAN's min_ped = 1 with a strict '>' test
FEWSHOT_EVERY: Final[int] = 10  # few-shot keeps every 10th training window
COORD_DECIMALS: Final[int] = 4  # Social-GAN rounds positions to 4 decimals before windowing
POSITION_LIMIT_M: Final[float] = 1000.0  # |x| and |y| of every recorded and observed position [m]
FORECAST_LIMIT_M: Final[float] = POSITION_LIMIT_M * (1 + 2 * T_PRED)
"""|x| and |y| of every forecast position [m]: the farthest a straight extrapolation of recorded positions reaches
(25 km: a step of up to 2 x 1000 m, T_PRED steps on from |x| = 1000 m), so a constant-velocity forecast of any valid
recording fits and a future kilometres beyond it is a broken predictor."""
ID_LIMIT: Final[int] = 2**53  # frame and agent ids are whole numbers in [0, 2^53): float64 holds them exactly

TASKS: Final[dict[str, dict]] = {
    # task: observed steps, samples S, split layout
    "stochastic": {"obs_len": T_OBS, "num_samples": 20},
    "deterministic": {"obs_len": T_OBS, "num_samples": 1},
    "momentary": {"obs_len": T_OBS_MOMENTARY, "num_samples": 20},
    "fewshot": {"obs_len": T_OBS, "num_samples": 20},
    "domain": {"obs_len": T_OBS, "num_samples": 1},  # val = the target's val portion (the paper's protocol)
    "domain_strict": {"obs_len": T_OBS, "num_samples": 1},  # val = the source's own val portion
}
DOMAIN_TASKS: Final[tuple[str, ...]] = ("domain", "domain_strict")  # scene = a pair "X2Y" of scene letters
SPLITS: Final[tuple[str, ...]] = ("train", "val", "test")
