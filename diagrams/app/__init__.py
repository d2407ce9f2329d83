"""The application: the `admittance` command line and what it writes.

Built on the library (admittance.systems and the rest of admittance.diagrams), which never
imports it: ``cli`` (main, the subcommands and the Ctrl-C guard) and ``parser`` (the
options and the exit status), ``simulate``, ``bench``, ``compare``, ``grasp_compare``,
``stability_report``, ``grasp_stability_report``, ``spatial_bench``,
``spatial_stability_report`` (bench and stability on a spatial arm) and ``sweep/`` (the
subcommands' work), ``result_folder`` (folders that are complete or absent, and only ever
the tool's own), ``formatting`` (how numbers are written for people), ``progress`` (the
stage lines on stderr), ``interrupts`` (Ctrl-C held back where a cut would not be clean)
and the hardware split's ``station`` and ``control`` commands (in ``cli``).
"""
