"""The application: the `admittance` command line and what it writes.

Built on the library (admittance.systems and the rest of admittance.diagrams), which never
imports it: ``cli`` (the parser, main and its Ctrl-C guard), ``simulate``, ``bench``,
``compare``, ``stability_report`` and ``sweep/`` (the subcommands' work), ``result_folder``
(folders that are complete or absent), ``formatting`` (how numbers are written for people),
``progress`` (the stage lines on stderr) and ``interrupts`` (Ctrl-C held back where a cut
would not be clean).
"""
