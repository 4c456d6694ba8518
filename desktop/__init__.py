"""Desktop-only tools: the ``pdr`` command, plots and the walk simulator.

Not packaged into the phone app (``buildozer.spec`` excludes this folder);
nothing in :mod:`core` imports it.
"""
