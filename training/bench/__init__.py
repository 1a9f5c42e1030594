"""Every benchmark of the project (``python -m training bench``; the collector is :mod:`training.bench.collect`).

One module per concept, in pipeline order: ``foundation`` (skin model, colour), ``sim``, ``data``, ``fit``,
``train``, ``addon`` (the Blender add-on's bake), ``runtime`` (the shipped ``exporters``: inference, texel
table, bake), ``validate``, ``cluster``.  They sit above the science packages (they may import any of them)
and below ``training.commands``; nothing but the collector and the tests imports them.
"""
