"""The sweep itself: combinations -> resolved scenes and their run ids -> runs (serial, or on Dask) -> the folder.

:func:`run_sweep` resolves every combination in the calling process (a run is identified by the hash of its
resolved scene, :func:`run_id`), skips those whose record is already on disk, and runs the others: in this
process with ``client=None``, else as one Dask task each on ``client``'s cluster (:func:`sweep_client` makes a
local cluster of worker processes, or connects to an existing scheduler: :mod:`volspring.sweep._cluster`). What a
task carries is the resolved scene (a small dict) and the options; the bytes of the mesh files the scenes name
are scattered once and shared by every task (:func:`_mesh_files`), so the workers need no access to the caller's
files, and a ``[compare]`` reference is made once per body (a task of its own) and shared by its runs. Records
come back to the calling process, which writes them as they arrive (:mod:`volspring.sweep._table`).

A run that fails is a record with its error (:func:`~volspring.sweep._measure.run_scene` does not raise for the
run's own failures; a run whose worker dies at every try, Dask's ``KilledWorker``, is recorded so too). A worker
lost mid-run is not a failure: Dask runs its tasks again on the others (a local cluster's nanny also restarts it).
Only runs lost to the cluster itself (the scheduler gone) are left without a record, listed in
:attr:`SweepResult.missing`; running the same sweep again computes them.
"""

from __future__ import annotations

import copy
import hashlib
import json
import logging
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from meshing._io import atomic_path
from volspring.sweep._cluster import BLAS_ENVIRONMENT, finishing
from volspring.sweep._measure import reference_key, reference_of, run_scene
from volspring.sweep._parameters import sweep_combinations
from volspring.sweep._table import TABLE_NAME, read_record, table_columns, write_record, write_table

if TYPE_CHECKING:
    from distributed import Client

__all__ = ["RECORD_FORMAT", "SweepResult", "run_id", "run_sweep"]

logger = logging.getLogger(__name__)

#: The version of a run record's content: part of every run id, so records of another version are run again.
RECORD_FORMAT = 1
#: Seconds between two rewrites of results.csv while runs finish (it is also written at the end).
TABLE_INTERVAL = 2.0


@dataclass(frozen=True, eq=False)
class SweepResult:
    """What :func:`run_sweep` did.

    Attributes
    ----------
    table : Path
        ``OUT/results.csv``.
    records : tuple of dict
        One per combination, in the sweep's order (the records of :attr:`missing` runs left out).
    executed : int
        Runs computed by this call.
    skipped : int
        Runs found on disk and not computed again.
    missing : tuple of str
        Run ids left without a record (their tasks lost to the cluster); run the sweep again to compute them.
    """

    table: Path
    records: tuple
    executed: int
    skipped: int
    missing: tuple = ()

    @property
    def complete(self) -> bool:
        """Every combination has its record."""
        return not self.missing

    @property
    def failed(self) -> int:
        """Records of runs that failed or diverged."""
        return sum(record["status"] != "done" for record in self.records)


def run_id(scene: dict, *, files: Mapping[str, str] | None = None, probes: Mapping[str, Sequence[float]] | None = None,
           frequencies: int = 0) -> str:
    """The id of a run: 16 hex digits of the SHA-256 of its resolved scene, the contents of the mesh files it
    reads (``files``: name -> SHA-256), what it measures (probes, frequencies) and :data:`RECORD_FORMAT`.

    >>> run_id({"duration": 1.0}) == run_id({"duration": 1.0}) != run_id({"duration": 2.0})
    True
    """
    measured = {"probes": probes or {}} | ({"frequencies": frequencies} if frequencies else {})
    text = json.dumps({"format": RECORD_FORMAT, "scene": scene, "files": files or {}, **measured},
                      sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def run_sweep(scene_path: str | os.PathLike[str], parameters: Mapping[str, Sequence[Any]] | None = None,
              out: str | os.PathLike[str] = "sweep", *, random: Mapping[str, Sequence[float]] | None = None,
              samples: int | None = None, seed: int = 0, client: Client | None = None,
              probes: Mapping[str, Sequence[float]] | None = None, frequencies: int = 0,
              callback: Callable[[dict, int, int], None] | None = None, rerun_failed: bool = False) -> SweepResult:
    """Run a scene file once per combination of parameter values; write one record per run and a table.

    Parameters
    ----------
    scene_path : path-like
        A scene file (``.toml``, :mod:`volspring.scene_file`); its ``output.folder`` is ignored (no frames).
    parameters : mapping of str to sequence, optional
        The grid: key path (as ``--set`` takes it) -> values; one run per combination of values.
    out : path-like
        The sweep's folder: ``results.csv``, ``sweep.json`` and ``runs/RUN_ID/run.json``.
    random : mapping of str to (2,) sequence, optional
        Key path -> ``(low, high)``, ``samples`` draws from a generator of ``seed``
        (:func:`~volspring.sweep._parameters.sweep_combinations`).
    samples : int, optional
    seed : int
    client : distributed.Client, optional
        Run on this Dask cluster (:func:`sweep_client`); None runs serially in this process.
    probes : mapping of str to (3,) float, optional
        Named points [m]: the displacement of the node nearest each is measured.
    frequencies : int
        Also measure the scene's lowest natural frequencies at rest, this many (:func:`run_scene`).
    callback : callable, optional
        ``callback(record, done, total)`` as each run's record is on disk (``done`` counts the skipped runs too).
    rerun_failed : bool
        Compute again the runs whose record on disk is a failure (a diverged run is computed again too).

    Returns
    -------
    SweepResult

    Raises
    ------
    SceneFileError
        For a scene file that cannot be read, or parameters that no combination can apply (every one refused).
    ValueError
        For parameters that make no sweep (:func:`~volspring.sweep._parameters.sweep_combinations`).

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> beam = Path(__file__).parents[2] / "examples" / "scenes" / "beam.toml"
    >>> out = Path(tempfile.mkdtemp())
    >>> coarse = {"bodies[0].size": [0.1], "duration": [0.03]}
    >>> result = run_sweep(beam, {**coarse, "bodies[0].material.E": [1e6, 2e6]}, out)
    >>> result.executed, [record["status"] for record in result.records], (out / "results.csv").is_file()
    (2, ['done', 'done'], True)
    >>> run_sweep(beam, {**coarse, "bodies[0].material.E": [1e6, 2e6, 4e6]}, out).executed
    1
    """
    from volspring.scene_file import SceneFileError, load_toml, resolve_scene, set_value

    scene_path, out = Path(scene_path), Path(out)
    raw = load_toml(scene_path)
    combinations = sweep_combinations(parameters, random=random, samples=samples, seed=seed)
    probes = {name: [float(value) for value in point] for name, point in (probes or {}).items()}
    measures: dict[str, Any] = {"probes": probes, "frequencies": int(frequencies)}
    resolved: list[dict | None] = []
    refused: list[SceneFileError] = []
    for combination in combinations:
        scene = copy.deepcopy(raw)
        try:
            for key, value in combination.items():
                set_value(scene, key, value)
            resolved.append(resolve_scene(scene))
        except SceneFileError as error:
            resolved.append(None)
            refused.append(error)
    if len(refused) == len(combinations):
        raise refused[0]
    files = _mesh_files([scene for scene in resolved if scene is not None], scene_path.parent)
    digests = {name: entry["sha256"] for name, entry in files.items()}
    runs: list[tuple[str, dict, dict | None, SceneFileError | None]] = []  # (id, combination, scene, refusal)
    refusals = iter(refused)
    for combination, scene in zip(combinations, resolved):
        if scene is None:
            error = next(refusals)
            runs.append((run_id({"refused": combination, "error": str(error)}), combination, None, error))
        else:
            used = {name: digests[name] for name in _mesh_names(scene) if name in digests}
            runs.append((run_id(scene, files=used, probes=probes, frequencies=int(frequencies)), combination, scene,
                         None))

    layout = (list(combinations[0]), probes)
    _write_json(out / "sweep.json", {"scene_file": str(scene_path.resolve()), "grid": dict(parameters or {}),
                                     "random": {key: list(bounds) for key, bounds in (random or {}).items()},
                                     "samples": samples, "seed": seed, **measures,
                                     "runs": [identifier for identifier, *_ in runs]})
    on_disk, pending = {}, {}
    for identifier, combination, scene, error in runs:
        record = read_record(out, identifier)
        if record is not None and not (rerun_failed and record.get("status") != "done"):
            on_disk[identifier] = record
        elif identifier not in pending:
            pending[identifier] = (combination, scene, error)
    skipped, total = len({identifier for identifier, *_ in runs if identifier in on_disk}), len(set(r[0] for r in runs))
    logger.info("sweep of %d runs: %d on disk, %d to compute", total, skipped, len(pending))
    table = out / TABLE_NAME
    progress = {"done": skipped, "executed": 0}
    written = [time.monotonic()]  # when the table was last written

    def finish(identifier, record):
        combination, scene, _ = pending[identifier]
        record = {"run": identifier, "parameters": combination, **record, "scene": scene,
                  "files": {name: digests[name] for name in _mesh_names(scene or {}) if name in digests},
                  **measures}
        write_record(out, record)
        on_disk[identifier] = record
        progress["done"] += 1
        progress["executed"] += 1
        if time.monotonic() - written[0] > TABLE_INTERVAL:
            _write_table(table, runs, on_disk, layout)
            written[0] = time.monotonic()
        if callback is not None:
            callback(record, progress["done"], total)

    for identifier, (combination, scene, error) in list(pending.items()):
        if scene is None:  # refused before running: its row says why
            finish(identifier, _refused_record(error))
    runnable: dict[str, dict] = {}
    for identifier, (_, scene, _) in pending.items():
        if scene is not None:
            runnable[identifier] = scene
    base = str(scene_path.parent.resolve())
    missing = []
    try:
        if client is None:
            references: dict[str, Any] = {}  # a [compare] reference per key, made at its first run
            for identifier, scene in runnable.items():
                key = reference_key(scene)
                if key is not None and key not in references:
                    references[key] = reference_of(scene, base=base)
                finish(identifier, run_scene(scene, base=base, reference=references.get(key or ""), **measures)
                       | {"worker": _worker()})
        else:
            missing = _run_on_cluster(client, runnable, base, measures, files, finish)
    finally:
        _write_table(table, runs, on_disk, layout)
    if missing:
        logger.warning("%d of %d runs have no record (lost to the cluster); run the sweep again to compute them",
                       len(missing), total)
    records = tuple({**on_disk[identifier], "parameters": combination} for identifier, combination, *_ in runs
                    if identifier in on_disk)
    return SweepResult(table, records, progress["executed"], skipped, tuple(missing))


def _run_on_cluster(client, runnable, base, measures, files, finish) -> list:
    """Submit one task per run, ``finish`` each record as it arrives; returns the run ids lost to the cluster."""
    from distributed.scheduler import KilledWorker

    shared = client.scatter([files], hash=False)[0] if files else None  # once, shared by every task
    # A [compare] reference (a FEM solve) is one task per distinct key; the runs that share it get its result, sent
    # to each worker once, instead of every run solving it again.
    keys = {identifier: reference_key(scene) for identifier, scene in runnable.items()}
    references = {}
    for identifier, scene in runnable.items():
        if keys[identifier] is not None and keys[identifier] not in references:
            references[keys[identifier]] = client.submit(_reference_task, scene, base=base, files=shared, pure=False,
                                                         key=f"volspring-reference-{identifier}")
    calls = {identifier: (_run_task, (scene,), {"base": base, "measures": measures, "files": shared,
                                                 "reference": references.get(keys[identifier])})
             for identifier, scene in runnable.items()}
    missing = []
    try:
        for identifier, future in finishing(client, calls, prefix="volspring-sweep"):
            try:
                record = future.result()
            except KilledWorker as error:  # the run killed its worker at every try (memory, a crash): its row
                record = {**_refused_record(error), "error_type": "KilledWorker"}
            except Exception as error:  # lost to the cluster, not the run's failure: no record, run it next time
                logger.warning("run %s: no result from the cluster (%s: %s)", identifier, type(error).__name__, error)
                missing.append(identifier)
                continue
            finish(identifier, record)
    finally:
        client.cancel(list(references.values()))  # an interruption leaves no reference solving on the cluster
    return missing


def _run_task(scene, *, base, measures, files, reference=None):
    """A worker's task: the scattered mesh files written to this machine once, then :func:`run_scene`."""
    return run_scene(_local(scene, files), base=base, reference=reference, **measures) | {"worker": _worker()}


def _reference_task(scene, *, base, files):
    """A worker's task: the ``[compare]`` reference shared by the runs of one :func:`reference_key`."""
    return reference_of(_local(scene, files), base=base)


def _local(scene, files):
    """``scene`` with the names of the scattered mesh files replaced by their copies on this machine."""
    if not files:
        return scene
    scene = copy.deepcopy(scene)
    for spec in scene["bodies"]:
        if "mesh" in spec and spec["mesh"] in files:
            spec["mesh"] = str(_materialised(files[spec["mesh"]]))
    return scene


def _materialised(entry) -> Path:
    """The path of a scattered mesh file on this machine, written on first use (with its companions)."""
    import tempfile

    folder = Path(tempfile.gettempdir()) / f"volspring-sweep-{entry['sha256'][:16]}"
    for name, data in entry["contents"].items():
        path = folder / name
        if not path.is_file():
            with atomic_path(path) as temporary:
                temporary.write_bytes(data)
    return folder / entry["name"]


def _mesh_names(scene) -> list:
    return [spec["mesh"] for spec in scene.get("bodies", []) if isinstance(spec, dict) and "mesh" in spec]


def _mesh_files(scenes, base) -> dict:
    """Name -> ``{"name", "sha256", "contents": {file name: bytes}}`` of every mesh file the scenes name (an
    XDMF file with its HDF5 data beside it); files that cannot be read are left to the runs to report."""
    files = {}
    for name in dict.fromkeys(name for scene in scenes for name in _mesh_names(scene)):
        path = base / name
        companions = [path] + ([path.with_suffix(".h5")] if path.suffix.lower() == ".xdmf" else [])
        try:
            contents = {file.name: file.read_bytes() for file in companions if file.is_file()}
        except OSError:
            continue
        if path.name not in contents:
            continue
        digest = hashlib.sha256(b"".join(hashlib.sha256(data).digest() for _, data in sorted(contents.items())))
        files[name] = {"name": path.name, "sha256": digest.hexdigest(), "contents": contents}
    return files


def _refused_record(error) -> dict:
    from volspring.sweep._measure import SOLVER

    return {"status": "failed", "error": " ".join(str(error).split()), "error_type": type(error).__name__,
            "solver": dict.fromkeys(SOLVER), "measured": {}, "seconds": {"wall": None, "build": None,
                                                                        "stepping": None}, "warnings": []}


def _worker() -> dict:
    """Where a run ran, and what sets its speed there: BLAS threads, and whether the compiled kernels ran (they change
    the times a record holds, never its numbers: :mod:`volspring.kernels`)."""
    import socket

    from volspring.kernels import active

    return {"host": socket.gethostname(), "pid": os.getpid(),
            "blas_threads": {name: os.environ.get(name) for name in BLAS_ENVIRONMENT}, "kernels": active()}


def _write_table(table, runs, on_disk, layout) -> None:
    """Write the records of ``runs`` on disk as the table; ``layout`` is ``(swept key paths, probes)``."""
    rows = [{**on_disk[identifier], "parameters": combination} for identifier, combination, *_ in runs
            if identifier in on_disk]
    parameters, probes = layout
    write_table(table, rows, table_columns(parameters, probes, rows))


def _write_json(path, data) -> None:
    with atomic_path(path) as temporary:
        temporary.write_text(json.dumps(data, indent=1, default=str) + "\n")
