"""fivecal.procedures: the named test procedures built on the core, one module
each, matching cpp/include/fivecal/procedures/: :mod:`.dbb` (four-step, Wang
path, circular test), :mod:`.tango` (the thesis' probing plan), :mod:`.sphere_test`
(the machine as a CMM), :mod:`.machining` (machining tests in error-sensitive
directions), :mod:`.probing_stats` (repeated-probing statistics)."""
