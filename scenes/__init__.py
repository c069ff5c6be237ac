"""The shipped scene descriptions and fidelity plans, installed as ``mincam_render.scene_data``.

This folder is the one copy: a clone edits it, ``pip install -e`` maps the package
name onto it, and a wheel carries it as package data (``pyproject.toml``). The
package reads it with :mod:`importlib.resources` through
:mod:`mincam_render.core.package_data`; there is no code here.
"""
