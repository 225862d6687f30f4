"""Loading volreel's ParaView reader (paraview_reader.py) into pvpython or the ParaView GUI.

    pvpython:  from volreel import pvplugin; pvplugin.load(globals())
               reader = VolreelReader(FileName="turbulence.vreel")
    paraview:  paraview --script /path/to/volreel/paraview_startup.py
               (then VolreelReader(FileName=...) in its Python shell)

Where ParaView's own plugin loader works, `paraview --plugin /path/to/volreel/paraview_reader.py`
does the same. Debian 12's ParaView 5.11 runs on Python 3.11, whose `inspect` no longer has the
`getargspec` that ParaView 5.11's Python plugin support imports; load() puts the equivalent back
before loading the plugin.
"""

import inspect
from collections import namedtuple
from pathlib import Path

READER = Path(__file__).resolve().with_name("paraview_reader.py")


def _restore_getargspec():
    if hasattr(inspect, "getargspec"):
        return
    ArgSpec = namedtuple("ArgSpec", "args varargs keywords defaults")

    def getargspec(func):
        spec = inspect.getfullargspec(func)
        return ArgSpec(spec.args, spec.varargs, spec.varkw, spec.defaults)

    inspect.getargspec = getargspec


def load(ns=None):
    """Loads the reader; with `ns` (e.g. globals()), VolreelReader is defined there."""
    _restore_getargspec()
    from paraview.simple import LoadPlugin

    LoadPlugin(str(READER), ns=ns)
