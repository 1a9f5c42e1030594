"""Validation of the model (paper §6, docs/contracts.md §6): the rendering gate, its tables, the Mitsuba 3 path, strips.

Modules: ``mixture`` (our Monte Carlo renderer of a K-media mixture, the rendering gate's renderer),
``gate`` (ground truth, joint-optimised fits, network and baseline media, renders, cache), ``baselines``
(Chiang 2016 / Wrenninge 2017 albedo inversion), ``metrics`` (colour and edge-image Delta E76, SAM, bands),
``profile_set`` (Table 3 from the validation fits), ``tables`` (tables.md / tables.json), ``figures``,
``paper`` (the paper's numbers), ``run`` (``python -m training validate``: the steps in order), ``stages``
(its computing: fits, renders, network, baseline scale), ``assemble`` (the tables' parts from those),
``record`` (the typed record and its JSON form, tables.json), ``run_figures`` (the run's figures), ``compare``
(``python -m training mitsuba``), ``strips`` (the teaser-like sphere strips), ``bench``, ``trends``,
``decomposition`` (§8's K = 3 decomposition and Figs. 7-9 from the shipped model).
"""
