"""Benchmark of a spatial-arm scenario: one discrete step of the loop against the bare plant's.

The spatial arm's plant is discrete (SAP, point contact, ``time_step``) and every controller
is sampled at the same period, so the loop has no derivative evaluations to count: the
comparable unit is ONE DISCRETE STEP, timed as one ``Simulator.AdvanceTo`` over N steps
divided by N (the plant's SAP solve, every controller's periodic update, the output ports
they pull and the loggers: what a run pays per step). ``CalcForcedDiscreteVariableUpdate``
would not do: it runs only forced events, which the plant declares and the project's
sampled systems (periodic events) do not.

``run_spatial_benchmark(scenario, repeat)`` measures, in one call and in this process's CPU
time (``time.process_time``: other processes on a shared machine barely move it):

* the whole run (``repeat`` runs of AdvanceTo over the scenario's duration, after a
  warm-up), per step;
* IN CONTACT, the headline: from the loop's state at the end of a run (the tool pressing
  with Fr), the loop and the FLOOR (the same plant, tool and table, no controller: the
  loop's last actuation held constant) each advanced over ``CONTACT_STEPS`` steps,
  interleaved ``repeat`` times, the least of each; their ratio;
* the Python callbacks, in one extra profiling run (``run.profiling.CallbackProfiler``): calls per
  step and the time inside each.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Context, Diagram, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from admittance.diagrams.robots.spatial_arm.loop import (
    BuildSpatialLoop,
    SetSpatialInitialConditions,
    SpatialLoop,
)
from admittance.diagrams.robots.spatial_arm.plant import AddSpatialArm
from admittance.diagrams.robots.spatial_arm.scenario import SpatialScenario
from admittance.diagrams.run.profiling import (
    CallbackProfiler,
    named_subsystems,
    python_system_classes,
)
from admittance.diagrams.views.formatting import number, seconds

__all__ = [
    "CONTACT_STEPS",
    "format_spatial_benchmark",
    "run_spatial_benchmark",
]

#: Steps of each in-contact timing (the loop's and the floor's), from the pressed state.
CONTACT_STEPS = 500


def _silent(stage: str) -> None:
    pass


def _steps(scenario: SpatialScenario, duration: float) -> int:
    return int(round(duration / scenario.time_step))


def _whole_run(loop: SpatialLoop) -> tuple[float, Simulator]:
    """CPU time of AdvanceTo over the scenario's duration, and the simulator at its end."""
    simulator = Simulator(loop.diagram)
    SetSpatialInitialConditions(loop, simulator.get_mutable_context())
    simulator.Initialize()
    start = time.process_time()
    simulator.AdvanceTo(loop.scenario.duration)
    return time.process_time() - start, simulator


def _advance_from(diagram: Diagram, context: Context, steps: int, time_step: float) -> float:
    """CPU time of AdvanceTo over `steps` steps from a copy of `context`, s."""
    simulator = Simulator(diagram, context.Clone())
    simulator.Initialize()
    end = simulator.get_context().get_time() + steps * time_step
    start = time.process_time()
    simulator.AdvanceTo(end)
    return time.process_time() - start


def _build_floor(scenario: SpatialScenario, actuation: np.ndarray):
    """The same plant (arm, tool, table), its actuation held at `actuation`."""
    builder = DiagramBuilder()
    plant, _, _ = AddSpatialArm(builder, scenario)
    source = builder.AddSystem(ConstantVectorSource(actuation))
    source.set_name("held_actuation")
    builder.Connect(source.get_output_port(), plant.get_actuation_input_port())
    diagram = builder.Build()
    diagram.set_name("floor")
    return diagram, plant


def _profile(scenario: SpatialScenario) -> dict:
    """One whole run with every Python calc counted and timed (run.profiling.CallbackProfiler)."""
    profiler = CallbackProfiler()
    profiler.patch(python_system_classes(BuildSpatialLoop(scenario).diagram))
    try:
        loop = BuildSpatialLoop(scenario)
        names = {id(system): name for name, system in named_subsystems(loop.diagram)}
        cpu, _ = _whole_run(loop)
    finally:
        profiler.restore()
    steps = _steps(scenario, scenario.duration)
    callbacks = sorted(
        (
            {
                "name": f"{names.get(system_id, '?')}.{method}",
                "calls_per_step": calls / steps,
                "time": inside,
                "per_step_us": 1e6 * inside / steps,
                "mean_us": 1e6 * inside / calls,
            }
            for (system_id, method), (calls, inside) in profiler.entries.items()
        ),
        key=lambda entry: -entry["time"],
    )
    return {
        "profiled_cpu_time": cpu,
        "time_in_callbacks": profiler.top_level_time,
        "per_step_us": 1e6 * profiler.top_level_time / steps,
        "callbacks": callbacks,
    }


def run_spatial_benchmark(
    scenario: SpatialScenario, repeat: int = 3, progress: Callable[[str], None] = _silent
) -> dict:
    """Times one discrete step of the spatial loop and of its floor (see the module).

    Returns:
        A JSON-serialisable dict: ``scenario``, ``repeat``, ``whole_run``, ``in_contact``
        (``loop_step_us``, ``floor_step_us``, ``ratio``, ``force``), ``python``. Times in
        seconds unless a key says otherwise.
    """
    if repeat < 1:
        raise ValueError(f"repeat must be >= 1, got {repeat}")
    steps = _steps(scenario, scenario.duration)
    progress("warm-up run of the loop")
    loop = BuildSpatialLoop(scenario)
    _, simulator = _whole_run(loop)
    progress(f"{repeat} timed run(s) of the loop")
    whole = [_whole_run(loop)[0] for _ in range(repeat)]

    context = simulator.get_context()
    force = float(
        loop.table_force.contact_force_output.Eval(loop.table_force.GetMyContextFromRoot(context))[
            0
        ]
    )
    actuation = loop.pid.actuation_output.Eval(loop.pid.GetMyContextFromRoot(context)).copy()
    floor, plant = _build_floor(scenario, actuation)
    floor_context = floor.CreateDefaultContext()
    state = loop.plant.GetPositionsAndVelocities(loop.plant.GetMyContextFromRoot(context))
    floor_context.SetTime(context.get_time())
    plant.SetPositionsAndVelocities(plant.GetMyMutableContextFromRoot(floor_context), state)

    progress(f"in contact: {CONTACT_STEPS} steps of the loop and of the floor, {repeat + 1} x")
    loop_times, floor_times = [], []
    for _ in range(repeat + 1):  # interleaved, so that both see the same machine
        loop_times.append(_advance_from(loop.diagram, context, CONTACT_STEPS, scenario.time_step))
        floor_times.append(_advance_from(floor, floor_context, CONTACT_STEPS, scenario.time_step))
    loop_step, floor_step = min(loop_times) / CONTACT_STEPS, min(floor_times) / CONTACT_STEPS

    progress("profiling run (every Python calc timed)")
    python = _profile(scenario)
    return {
        "scenario": {
            "name": scenario.name,
            "duration": scenario.duration,
            "time_step": scenario.time_step,
            "controller": scenario.controller.kind,
            "sensor": scenario.sensor.kind,
        },
        "repeat": repeat,
        "whole_run": {
            "steps": steps,
            "cpu_time": sorted(whole),
            "step_us": 1e6 * min(whole) / steps,
        },
        "in_contact": {
            "steps": CONTACT_STEPS,
            "force": force,
            "loop_step_us": 1e6 * loop_step,
            "floor_step_us": 1e6 * floor_step,
            "ratio": loop_step / floor_step,
        },
        "python": python,
    }


def format_spatial_benchmark(report: dict) -> str:
    """A readable table of a ``run_spatial_benchmark`` report."""
    scenario, whole, contact = report["scenario"], report["whole_run"], report["in_contact"]
    python = report["python"]
    lines = [
        f"Benchmark of {scenario['name']} (spatial arm, discrete plant, step "
        f"{seconds(scenario['time_step'])}, {scenario['controller']}, sensor "
        f"{scenario['sensor']}): CPU time of this process, least of {report['repeat']} run(s)",
        "",
        f"whole run ({number(scenario['duration'], ' s')}, {whole['steps']} steps): "
        f"{seconds(1e-6 * whole['step_us'])} per step",
        f"in contact (F = {number(contact['force'], ' N')}, {contact['steps']} steps from the "
        "pressed state):",
        f"  one step of the loop   {seconds(1e-6 * contact['loop_step_us']):>10}",
        f"  one step of the floor  {seconds(1e-6 * contact['floor_step_us']):>10}"
        "   (the same plant, actuation held, no controller)",
        f"  loop / floor           {number(contact['ratio'])} x",
        "",
        f"Python callbacks (profiling run, {seconds(python['profiled_cpu_time'])} CPU): "
        f"{seconds(1e-6 * python['per_step_us'])} per step inside them",
        f"  {'callback':52}{'per step':>10}{'mean':>10}{'per step':>12}",
    ]
    for entry in python["callbacks"]:
        lines.append(
            f"  {entry['name']:52}{number(entry['calls_per_step']):>10}"
            f"{seconds(1e-6 * entry['mean_us']):>10}{seconds(1e-6 * entry['per_step_us']):>12}"
        )
    return "\n".join(lines)
