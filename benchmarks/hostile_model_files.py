"""Time and peak memory of refusing the red team's hostile model files, beside reading normal ones.

    OMP_NUM_THREADS=1 python benchmarks/hostile_model_files.py

Each file is read in a fresh interpreter (stable-baselines3 and torch imported first, then the one load call timed),
its address space capped at what the imports took plus ``HEADROOM_BYTES``, so a regression fails instead of taking
the machine. Printed per file: its size, the outcome (loaded, or the start of the refusal), the wall time of the
load call, the process's peak resident memory and how far it rose during the call. The files:

- ``sb3 normal``: a PPO ``MlpPolicy`` as SB3 saves it (Pendulum-v1's spaces, SB3's default net_arch);
- ``sb3 red team``: that zip with net_arch [40000, 40000] and a ``policy.pth`` of one stride-0 tensor,
  ``torch.zeros(1).expand(10**6, 10**6)`` (10^12 weights counted, 4 bytes held; the old loader built the 6.4 GB
  network before refusing);
- ``sb3 expanded network``: the same net_arch, ``policy.pth`` holding every tensor of that network by its own name
  and shape, each one number expanded;
- ``ppo normal``: the shipped ``ppo-predictions`` policy file;
- ``ppo red team``: a 1.5 KB policy file stating net_arch [40000, 40000] (the old loader built it first);
- ``ppo expanded network``: that file with the network's tensors, each one number expanded.
"""

from __future__ import annotations

import argparse
import io
import json
import subprocess
import sys
import tempfile
import zipfile
from dataclasses import asdict
from pathlib import Path

from replays import strict_json

HEADROOM_BYTES = 4 * 2**30  # address space a child may add to what its imports took [bytes]
WIDE = [40000, 40000]  # the red team's net_arch [-]
CHILD = """
import resource, sys, time
from pathlib import Path
from replays import strict_json
import gymnasium as gym
import stable_baselines3  # noqa: F401
from st_sim.apps.navigation.ppo import load_policy
from st_sim.apps.navigation.sb3_zip import load_sb3_zip

kind, path = sys.argv[1], Path(sys.argv[2])
with open("/proc/self/status") as status:
    size_kb = next(int(line.split()[1]) for line in status if line.startswith("VmSize:"))
limit = size_kb * 1024 + int(sys.argv[3])
resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
before_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
start = time.perf_counter()
try:
    load_sb3_zip(path, gym.make("Pendulum-v1").action_space) if kind == "sb3" else load_policy(path)
    outcome = "loaded"
except (ValueError, MemoryError, RuntimeError) as err:
    outcome = f"{type(err).__name__}: {str(err).removeprefix(str(path) + ': ')}"
seconds = time.perf_counter() - start
peak_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(strict_json.dumps({"outcome": outcome, "seconds": seconds, "peak_mb": peak_kb / 1024,
                  "rise_mb": (peak_kb - before_kb) / 1024}))
"""


def torch_bytes(value: object) -> bytes:
    import torch

    buffer = io.BytesIO()
    torch.save(value, buffer)
    return buffer.getvalue()


def rewritten(source: Path, target: Path, members: dict[str, bytes]) -> Path:
    """A copy of the zip ``source`` with ``members`` replaced."""
    with zipfile.ZipFile(source) as original, zipfile.ZipFile(target, "w") as copy:
        for info in original.infolist():
            copy.writestr(info.filename, members.get(info.filename, original.read(info.filename)))
    return target


def expanded(state: dict) -> dict:
    """Each tensor of a (meta-device) state dict as one number expanded to its shape."""
    import torch

    return {key: torch.zeros(1).expand(tensor.shape) for key, tensor in state.items()}


def sb3_files(folder: Path) -> dict[str, Path]:
    """The SB3 zips: normal, the red team's, the expanded network."""
    import gymnasium as gym
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.policies import ActorCriticPolicy

    from st_sim.apps.navigation.held_weights import network_state

    env = gym.make("Pendulum-v1")
    normal = folder / "sb3-normal.zip"
    PPO("MlpPolicy", env, n_steps=64, batch_size=64, seed=0, device="cpu").save(normal)
    with zipfile.ZipFile(normal) as archive:
        data = json.loads(archive.read("data"))
    wide_data = strict_json.dumps({**data, "policy_kwargs": {"net_arch": WIDE}}).encode()
    network = network_state(ActorCriticPolicy, env.observation_space, env.action_space, lambda _: 0.0, net_arch=WIDE)
    return {"sb3 normal": normal,
            "sb3 red team": rewritten(normal, folder / "sb3-red-team.zip", {
                "data": wide_data, "policy.pth": torch_bytes({"x": torch.zeros(1).expand(10**6, 10**6)})}),
            "sb3 expanded network": rewritten(normal, folder / "sb3-expanded.zip", {
                "data": wide_data, "policy.pth": torch_bytes(expanded(network))})}


def ppo_files(folder: Path) -> dict[str, Path]:
    """The PPO policy files: the shipped one, the red team's, the expanded network."""
    from stable_baselines3.common.policies import ActorCriticPolicy

    from st_sim.apps.navigation.features import FeatureConfig
    from st_sim.apps.navigation.held_weights import network_state
    from st_sim.apps.navigation.ppo import FORMAT, policy_file, policy_kwargs, policy_spaces

    cfg = FeatureConfig(use_predictions=False)
    state = {"format": FORMAT, "features": asdict(cfg), "net_arch": WIDE, "extractor": "flat", "weights": {}}
    network = network_state(ActorCriticPolicy, *policy_spaces(cfg), lambda _: 0.0, **policy_kwargs(cfg, WIDE))
    red_team, shaped = folder / "ppo-red-team.pt", folder / "ppo-expanded.pt"
    red_team.write_bytes(torch_bytes(state))
    shaped.write_bytes(torch_bytes({**state, "weights": expanded(network)}))
    return {"ppo normal": policy_file("ppo-predictions")[0], "ppo red team": red_team, "ppo expanded network": shaped}


def measure(kind: str, path: Path) -> dict:
    """The child's figures for reading ``path`` (``kind``: "sb3" or "ppo")."""
    run = subprocess.run([sys.executable, "-c", CHILD, kind, str(path), str(HEADROOM_BYTES)], capture_output=True,
                         text=True)
    if run.returncode:
        sys.exit(f"hostile_model_files: the child reading {path} failed:\n{run.stderr}")
    return json.loads(run.stdout.splitlines()[-1])


def main() -> None:
    argparse.ArgumentParser(description=__doc__.split("\n")[0]).parse_args()
    with tempfile.TemporaryDirectory() as folder:
        files = {**sb3_files(Path(folder)), **ppo_files(Path(folder))}
        print(f"{'file':<22} {'size':>9} {'time':>8} {'peak RSS':>9} {'rise':>8}  outcome")
        normal_peak = {}
        for name, path in files.items():
            kind = name.split()[0]
            figures = measure(kind, path)
            normal_peak.setdefault(kind, figures["peak_mb"])
            print(f"{name:<22} {path.stat().st_size / 1024:>6.1f} KB {figures['seconds']:>6.3f} s "
                  f"{figures['peak_mb']:>6.0f} MB {figures['rise_mb']:>5.0f} MB  {figures['outcome'][:110]}"
                  + ("" if name.endswith("normal") else
                     f" [{figures['peak_mb'] - normal_peak[kind]:+.0f} MB beside the normal file's peak]"))


if __name__ == "__main__":
    main()
