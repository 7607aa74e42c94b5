"""Many inputs or seeds through one navkit function: in process, on a LocalCluster, or on Dask.

See :mod:`navkit.batch.engine` for the execution model (tasks, manifest, resume) and
``docs/scale.md`` for running on SSH, SLURM and Kubernetes clusters.
"""

from navkit.batch.engine import (
    DONE_MARKER,
    MANIFEST,
    BatchResult,
    BatchSettings,
    BatchTask,
    execute_task,
    is_complete,
    iter_batch,
    local_cluster,
    run_batch,
    settings_hash,
)
from navkit.batch.jobs import mission_sweep_tasks, parse_seeds
from navkit.batch.summary import Rate, summarize, wilson_interval

__all__ = [
    "DONE_MARKER",
    "MANIFEST",
    "BatchResult",
    "BatchSettings",
    "BatchTask",
    "Rate",
    "execute_task",
    "is_complete",
    "iter_batch",
    "local_cluster",
    "mission_sweep_tasks",
    "parse_seeds",
    "run_batch",
    "settings_hash",
    "summarize",
    "wilson_interval",
]
