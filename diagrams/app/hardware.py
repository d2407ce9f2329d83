"""`admittance station` and `admittance control`: the two processes of the hardware split
(docs/evidence/hardware.md), each on an LCM URL that keeps its packets on this machine.

    admittance station SCENARIO --lcm URL [--out DIR] [--force]
    admittance control SCENARIO --lcm URL [--out DIR] [--force]

SIGINT or SIGTERM stops either one cleanly: the controller sends a last safe command, both
write what they measured, and the status is 0. A controller whose station goes silent
prints one line and exits with status 1.
"""

from __future__ import annotations

import signal
import sys
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from admittance.diagrams.results.folder import check_output_dir, result_folder
from admittance.diagrams.scenario.schema import ScenarioError

__all__ = ["control_command", "station_command", "stop_on_signals"]


@contextmanager
def stop_on_signals():
    """Within the block, SIGINT and SIGTERM set a flag instead of interrupting; yields the
    function that reads it."""
    caught: list[int] = []
    previous = {
        number: signal.signal(number, lambda signum, frame: caught.append(signum))
        for number in (signal.SIGINT, signal.SIGTERM)
    }
    try:
        yield lambda: bool(caught)
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


def _setup(args):
    from pydrake.lcm import DrakeLcm

    from admittance.diagrams.hardware.config import load_hardware_config
    from admittance.diagrams.hardware.messages import check_lcm_url

    try:
        url = check_lcm_url(args.lcm)
    except ValueError as error:
        raise ScenarioError(str(error)) from None
    config = load_hardware_config(args.scenario, args.overrides)
    return config, DrakeLcm(url)


def station_command(args, progress) -> int:
    """Runs the station for the scenario's duration; writes timeseries.csv and metrics.json."""
    import yaml

    from admittance.diagrams.hardware.station import run_station, station_metrics

    config, lcm = _setup(args)
    out = Path(args.out) if args.out else Path("results") / f"{config.name}_station"
    check_output_dir(out, overwrite=args.force)
    if args.pacer:
        return _pace(config, lcm, out, args, progress)
    progress(f"station: {config.name}, {config.mode} mode, on {args.lcm}")
    sliders = _sliders(config, lcm, progress) if config.meshcat else None
    with stop_on_signals() as stop:
        run = run_station(config, lcm, stop=stop, sliders=sliders)
    metrics = station_metrics(run, config)
    with result_folder(out, overwrite=args.force) as folder:
        data = np.column_stack([run.times, run.force, run.tip_height, run.hold])
        folder.write_with(
            "timeseries.csv",
            lambda path: np.savetxt(
                path,
                data,
                delimiter=",",
                header="time,force,tip_height,hold",
                comments="",
                fmt="%.9g",
            ),
        )
        folder.write_json("metrics.json", metrics)
        folder.write_text("scenario.yaml", yaml.safe_dump(vars(config), sort_keys=False))
    loss = metrics["command_loss_time"]
    final = float(run.force[-1]) if run.force.size else float("nan")
    peak = metrics["peak_force_after_command_loss"]
    print(
        f"station: {metrics['simulated_time']:.3f} s simulated at "
        f"{metrics['real_time_rate']:.2f}x real time; force at the end {final:.3f} N "
        f"(Fr {config.force_reference:g} N); "
        + (
            f"commands lost at {loss:.3f} s, peak force after {peak:.3f} N"
            if loss is not None
            else "no command loss"
        )
    )
    print(folder.describe(out))
    return 0


def _sliders(config, lcm, progress):
    """The station's Meshcat (localhost) with the law's sliders."""
    from admittance.diagrams.hardware.config import scenario_of
    from admittance.diagrams.hardware.sliders import ParameterSliders, station_meshcat

    meshcat = station_meshcat()
    law = scenario_of(config).admittance
    sliders = ParameterSliders(
        meshcat,
        lcm,
        force_reference=config.force_reference,
        gamma=law.gamma,
        alpha=law.alpha,
        max_force=config.max_force,
    )
    progress(f"meshcat: {meshcat.web_url()} (sliders: Fr, Gamma, alpha, Fmax)")
    return sliders


def _pace(config, lcm, out: Path, args, progress) -> int:
    """`station --pacer`: the robot's messages at its rate without a simulation."""
    from admittance.diagrams.hardware.pacer import StatusPacer

    progress(f"pacer: status and wrench at {config.rate:g} Hz for {config.duration:g} s")
    from admittance.diagrams.hardware.config import hardware_parts, scenario_of

    positions = hardware_parts(scenario_of(config)).home_positions
    pacer = StatusPacer(lcm, rate=config.rate, positions=positions, force=config.force_reference)
    with stop_on_signals() as stop:
        figures = pacer.run(config.duration, stop)
    with result_folder(out, overwrite=args.force) as folder:
        folder.write_json("pacer.json", figures)
    trip = figures["round_trip"]
    print(
        f"pacer: {figures['statuses']} statuses, {figures['unanswered']} unanswered, "
        f"{figures['answered_within_period']} answered within the period; round trip p50 "
        f"{_ms(trip['p50'])} p99 {_ms(trip['p99'])} max {_ms(trip['max'])}"
    )
    print(folder.describe(out))
    return 0


def control_command(args, progress) -> int:
    """Runs the controller until the status clock reaches the duration; writes timing.json,
    events.log and trace.csv."""
    from admittance.diagrams.hardware.controller import AdmittanceController, StationGoneError

    config, lcm = _setup(args)
    out = Path(args.out) if args.out else Path("results") / f"{config.name}_control"
    check_output_dir(out, overwrite=args.force)
    controller = AdmittanceController(config, lcm, newest_only=True)
    progress(f"control: {config.name} at {config.rate:g} Hz on {args.lcm}, waiting for status")
    failure = None
    with stop_on_signals() as stop:
        try:
            outcome = controller.run(
                stop,
                lambda t, force, offset: progress(
                    f"t = {t:.1f} s: force {force:.2f} N, offset {offset * 1e3:.2f} mm"
                ),
            )
        except StationGoneError as error:
            failure, outcome = str(error), "station gone"
    trace = controller.trace
    with result_folder(out, overwrite=args.force) as folder:
        folder.write_json(
            "timing.json",
            {**controller.timing.summary(), "stability": controller.stability_summary()},
        )
        folder.write_text(
            "events.log",
            "".join(f"t={e.time:.4f} s  {e.what}\n" for e in controller.events),
        )
        data = np.column_stack([trace.times, trace.force, trace.offset])
        folder.write_with(
            "trace.csv",
            lambda path: np.savetxt(
                path, data, delimiter=",", header="time,force,offset", comments="", fmt="%.9g"
            ),
        )
    if failure is not None:
        print(f"admittance: error: {failure}; results in {out}/", file=sys.stderr)
        return 1
    timing = controller.timing.summary()
    latency = timing["latency"]
    print(
        f"control: {outcome} after {timing['cycles']} cycles; latency p50 "
        f"{_ms(latency['p50'])} p99 {_ms(latency['p99'])} max {_ms(latency['max'])}; "
        f"{timing['missed_deadlines']} missed deadlines"
    )
    print(folder.describe(out))
    return 0


def _ms(value) -> str:
    return "n/a" if value is None else f"{value * 1e3:.3f} ms"
