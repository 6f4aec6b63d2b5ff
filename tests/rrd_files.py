"""Reading .rrd recordings in the tests, with Rerun's own chunk reader (as the viewer reads them)."""

from __future__ import annotations

import warnings
from collections import defaultdict
from pathlib import Path

import rerun as rr


def rrd_reader(path: str | Path) -> rr.chunk.RrdReader:
    """Rerun's chunk reader, without its warning that the file has no footer (STCrowd writes none, on purpose)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="RRD file has no footer")
        return rr.chunk.RrdReader(str(path))


def read_rrd(path: str | Path) -> dict[str, dict[int | None, dict[str, object]]]:
    """entity path -> step (None for static) -> component column -> value."""
    entities: dict[str, dict[int | None, dict[str, object]]] = defaultdict(lambda: defaultdict(dict))
    for chunk in rrd_reader(path).stream():
        if chunk.entity_path.startswith("/__"):  # recording properties
            continue
        batch = chunk.to_record_batch()
        steps = batch.column("step").to_pylist() if "step" in batch.schema.names else [None] * batch.num_rows
        for name in (n for n in batch.schema.names if ":" in n):
            for step, value in zip(steps, batch.column(name).to_pylist(), strict=True):
                entities[chunk.entity_path][step][name] = value
    return entities


def logged_steps(path: str | Path) -> int:
    """Distinct ``step`` values in a recording."""
    steps: set[int] = set()
    for chunk in rrd_reader(path).stream():
        batch = chunk.to_record_batch()
        if "step" in batch.schema.names:
            steps |= set(batch.column("step").to_pylist())
    return len(steps)


def read_blueprint(path: str | Path) -> dict[str, dict[str, object]]:
    """The recording's one default blueprint: entity path in the blueprint store -> component -> last value."""
    reader = rrd_reader(path)
    stores = reader.blueprints()
    assert len(stores) == 1, f"{path}: {len(stores)} blueprints"
    parts: dict[str, dict[str, object]] = defaultdict(dict)
    for chunk in reader.stream(store=stores[0]):
        batch = chunk.to_record_batch()
        for name in (n for n in batch.schema.names if ":" in n):
            parts[chunk.entity_path][name.split(":", 1)[1]] = batch.column(name).to_pylist()[-1]
    return parts
