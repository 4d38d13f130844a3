"""The diagnosis' bench generators: records with known effects, for ``diagnose-bench``.

Not part of the product: ``fresco_bridge.diagnosis`` holds what ``diagnose`` runs, and imports
nothing from here (``tests/bridge/diagnosis/test_layering.py``). ``diagnose-bench`` imports
these modules only when it runs, from a checkout of the repository.

* ``synth``: the plain bench's records, generated on ``sim_actuator``'s rig with the
  candidates' own effect forms;
* ``realism``: the effects in the rig's physical forms (servo lag, compliant frame, ...);
* ``independent`` and ``independent_laws``: specimens and effects written anew from the
  physics, sharing no code with the rig or the candidates;
* ``bench``: items, generation (with an on-disk cache), blind diagnosis and the scoring.
"""
