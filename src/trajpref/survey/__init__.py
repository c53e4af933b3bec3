"""The human-evaluation study of the paper's Table 3, as a tool: build a blinded study folder
from a dataset and several methods, serve it to raters as a web page (answers in SQLite),
simulate raters for demos, and analyse the answers against ATS/FTS.

Modules: ``manifest`` (the study folder, read and checked), ``study`` (rendering and writing a
study), ``build`` (scene selection, sampling and scoring), ``store`` (the answers database),
``server`` (the web application), ``simulate`` (synthetic raters), ``analyze`` (the
statistics and the Table-3 layout), ``cli`` (the ``trajpref survey`` commands). Only ``build``
imports torch and the models; nothing is imported here.
"""
