"""Validation of the model (paper §6, SPEC §6): our mixture renderer, the Mitsuba 3 path and its strips.

Modules: ``mixture`` (our Monte Carlo renderer of a K-media mixture, the rendering gate's renderer),
``compare`` (``python -m training mitsuba``: Mitsuba vs ours vs the biophysical ground truth),
``strips`` (the teaser-like sphere strips), ``cli`` (``python -m training validate``), ``bench``.
"""
