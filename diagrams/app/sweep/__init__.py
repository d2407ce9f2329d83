"""`admittance sweep`: a grid or a Monte Carlo over scenario keys, in parallel, resumable.

A sweep is a base scenario (a built-in name or a YAML file, with ``--set`` overrides) and a
list of POINTS, each a mapping of dotted scenario keys to values that is applied on top of
the base (a point's value wins over a ``--set`` of the same key):

* ``--grid KEY=SPEC``: SPEC is a comma list (``1e4,5e4,1e5``, each value parsed as ``--set``
  parses it; ``[...]`` values may hold commas), ``linspace:A:B:N`` or ``logspace:A:B:N``
  (N values from A to B, evenly spaced in log for logspace; A and B in real units, not
  exponents). Several ``--grid`` flags form the Cartesian product, the last flag varying
  fastest.
* ``--random KEY=DIST`` with ``--samples N``: DIST is ``uniform:A:B``, ``loguniform:A:B``,
  ``normal:MEAN:STD``, ``randint:A:B`` (integers A..B inclusive) or ``choice:a,b,c``. The
  draws come from ``numpy.random.default_rng(seed)``: N values per ``--random`` flag, one
  flag after the other in the order given, so the same command always gives the same
  points. Combined with grids, every grid point runs the same N samples (common random
  numbers: differences between grid points are not sampling noise).

Every point is validated (``load_scenario``) before anything runs or is written; a bad
spec, key or value raises ``SweepError`` (a ``ScenarioError``: one line, exit status 2).

Each point is identified by a POINT ID, the first 16 hex digits of the SHA-256 of: the base
scenario's name and the SHA-256 of its YAML file, the ``--set`` list, the point's sorted
overrides and, for Monte Carlo points, the sample number. The same point of the same sweep
has the same id in every run, on every machine with the same numpy.

The folder ``--out DIR`` holds:

``sweep.json``
    The sweep's definition (``"definition"``: base scenario and its file's SHA-256,
    ``--set``, the ``--grid``/``--random`` specs, samples, seed, the number of points and
    a SHA-256 of their ids), written at the start, plus informational fields.
``points.jsonl``
    One JSON object per finished point, one line each, appended as the point finishes
    (one ``os.write`` of the whole line, then ``fsync``), in completion order::

        {"index": 3, "point_id": "9f0c...", "values": {"wall.stiffness": 1e5},
         "failed": false, "failure": null,
         "metrics": {"force_reference": 5.0, "peak_force": 37.4, ...}}

    ``metrics`` holds ``force_reference``, ``peak_force``, ``steady_state_force_error``,
    ``rms_force_error``, ``mean_abs_force_error_settled``, ``contact_losses``,
    ``first_contact_time``, ``force_min/max_while_wall_moves`` (wall moving), every other
    scalar of metrics.json but the integrator's bookkeeping, the settling time to 5 % of Fr
    after each event as ``settling_<kind>_<i>`` (``i`` counts events of that kind from 0;
    null = not settled before the next event), ``wall_time`` (the simulation's, as in
    metrics.json) and ``point_time`` (build + run + metrics, s). A
    point whose simulation diverges, or that raises ``ScenarioError``/``RuntimeError``,
    is recorded with ``"failed": true``, its one-line message in ``failure`` and only the
    times in ``metrics``; it does not stop the sweep.
``table.csv``
    One row per finished point, sorted by index: ``index, point_id``, the swept keys,
    ``failed, failure`` and the metrics (empty cell = null).
``summary.txt``
    What ``admittance sweep`` prints at the end: counts, failures, where tracking degrades
    (steady-state force error above 5 % of Fr), per range of each swept key, and the worst
    points by peak force and by RMS force error.
``summary_<key>.png``
    Per swept key: the metrics against the key's value (log axis for logspace/loguniform
    keys), failed points marked with red crosses along the bottom.

``table.csv``, ``summary.txt``, the plots and ``sweep.json`` are each written atomically
(a temporary file in DIR, then ``os.replace``).

RESUME. ``points.jsonl`` is the sweep's record. Run the same command again (after Ctrl-C, a
kill, a crash or a reboot) and every point already in it, failed ones included, is skipped;
only the others run. A torn last line (the process killed in the middle of a write) is
ignored and removed. If ``sweep.json`` describes a different sweep (another scenario file
content, ``--set``, spec, seed, ... or code that draws other points), the folder is refused
unless ``--force``, which starts over. Workers, engine and scheduler are not part of the
definition: a sweep started locally may be finished on a cluster. One sweep at a time may
run in a folder (a lock file, ``.sweep.lock``).

ENGINES. ``local`` (default) runs the points in a ``ProcessPoolExecutor`` of ``--workers``
processes (default: all cores), started with ``spawn`` (a fresh interpreter: no Drake state
is forked), one point at a time per worker. ``dask`` submits the same points to a
``dask.distributed`` cluster: the scheduler at ``--scheduler ADDRESS``, or a
``LocalCluster`` of ``--workers`` processes. Remote workers need this project installed, and
a YAML base scenario at the same absolute path (built-in names work anywhere).

The package, one module per part: ``specs`` (the axes), ``definition`` (the points,
validated), ``points`` (one simulated point, points.jsonl), ``folder`` (sweep.json, the
lock), ``summary`` (table.csv, summary.txt), ``plots`` and ``run`` (:func:`run_sweep`). The
worker pool and Ctrl-C are :mod:`admittance.diagrams.run.parallel`'s, shared with
``admittance compare``.
"""

from admittance.diagrams.app.sweep.definition import SweepDefinition, SweepPoint, define_sweep
from admittance.diagrams.app.sweep.points import point_metrics, read_points, run_point
from admittance.diagrams.app.sweep.run import SweepOutcome, run_sweep
from admittance.diagrams.app.sweep.specs import (
    GRID_FORMS,
    RANDOM_FORMS,
    GridAxis,
    RandomAxis,
    SweepError,
    parse_grid,
    parse_random,
)
from admittance.diagrams.app.sweep.summary import summarize, table_text
from admittance.diagrams.run.parallel import WorkerDiedError

__all__ = [
    "GRID_FORMS",
    "RANDOM_FORMS",
    "GridAxis",
    "RandomAxis",
    "SweepDefinition",
    "SweepError",
    "SweepOutcome",
    "SweepPoint",
    "WorkerDiedError",
    "define_sweep",
    "parse_grid",
    "parse_random",
    "point_metrics",
    "read_points",
    "run_point",
    "run_sweep",
    "summarize",
    "table_text",
]
