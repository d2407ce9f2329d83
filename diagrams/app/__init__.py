"""The application: the `admittance` command line and what it writes.

Built on the library (admittance.systems and the rest of admittance.diagrams), which never
imports it: ``cli`` (main, the subcommands and the Ctrl-C guard) and ``parser`` (the
options and the exit status), ``simulate`` (a run's result folder and its summary),
``bench_report`` (the file of ``bench --json``), ``progress`` (the stage lines on stderr),
``hardware`` (the hardware split's ``station`` and ``control`` commands) and ``sweep/``.
The work of ``bench``, ``compare``, ``grasp-compare`` and ``stability`` is each robot's
(``robots.<robot>.bench``, ``compare``, ``stability_report``), reached through its record;
folders that are complete or absent, and only ever the tool's own, are
``results.folder``'s, Ctrl-C held back where a cut would not be clean
``results.interrupts``', and how numbers are written for people ``views.formatting``'s.
"""
