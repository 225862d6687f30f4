# paraview --script /path/to/volreel/paraview_startup.py: loads volreel's reader into ParaView
# (pvplugin.py says why a script rather than --plugin on Debian 12).
import os
import sys

# ParaView's GUI runs a --script without __file__: there the module comes from PYTHONPATH alone.
if "__file__" in globals():
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from volreel import pvplugin  # noqa: E402

pvplugin.load(globals())
