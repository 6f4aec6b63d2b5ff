"""Every command of the guide ``docs/benchmark-your-policy.md`` runs as written on a fresh clone, in its order, with
small counts: ``--episodes N`` becomes 1 (a benchmark without it gets ``--episodes 1``) and ``--steps N`` becomes 256.
The commands run in a fresh folder that sees the repository's ``examples`` and ``results``, as a clone's root does."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
GUIDE = REPO / "docs" / "benchmark-your-policy.md"


def guide_commands(text: str) -> list[str]:
    """The commands of the guide's ``bash`` blocks, continuation lines joined and comments dropped."""
    commands = []
    for block in re.findall(r"```bash\n(.*?)```", text, flags=re.S):
        joined = re.sub(r"\\\n\s*", "", "\n".join(line.strip() for line in block.splitlines()))
        commands += [line for line in (re.sub(r"\s+#.*$", "", line).strip() for line in joined.splitlines())
                     if line and not line.startswith("#")]
    return commands


def small(command: str) -> str:
    """``command`` with small counts (see the module docstring)."""
    command = re.sub(r"--episodes \d+", "--episodes 1", command)
    command = re.sub(r"--steps \d+", "--steps 256", command)
    if " benchmark " in f"{command} " and "--episodes" not in command:
        command += " --episodes 1"
    return command


def test_the_guide_names_its_commands() -> None:
    commands = guide_commands(GUIDE.read_text())
    assert len(commands) >= 8 and all(c.startswith(("python ", "MY_POLICY_MODEL=")) for c in commands), commands


def test_every_command_of_the_guide_runs_as_written(tmp_path: Path) -> None:
    for name in ("examples", "results"):
        (tmp_path / name).symlink_to(REPO / name)
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(tmp_path)}
    for command in map(small, guide_commands(GUIDE.read_text())):
        words = shlex.split(command)
        assigned = dict(word.split("=", 1) for word in words if re.match(r"^[A-Z_]+=", word))
        words = [word for word in words if not re.match(r"^[A-Z_]+=", word)]
        words[0] = sys.executable if words[0] == "python" else words[0]
        done = subprocess.run(words, cwd=tmp_path, env={**env, **assigned}, capture_output=True, text=True,
                              timeout=1800)
        assert done.returncode == 0, f"{command}\n{done.stderr[-2000:]}"
