"""pvpython check of the ParaView reader: open a container, go to time step 3, compare the array
with `volreel decode`, switch the level of detail, save a screenshot.

    pvpython --force-offscreen-rendering paraview_check.py CONTAINER DECODED_F32 SCREENSHOT

with the volreel package on PYTHONPATH.
"""

import os
import sys

import numpy as np
from paraview import servermanager
from paraview.simple import (GetActiveViewOrCreate, GetAnimationScene, Render, ResetCamera,
                             SaveScreenshot, Show)
from vtkmodules.numpy_interface import dataset_adapter as dsa

import volreel

container, decoded_file, screenshot = sys.argv[1:4]
# The reader loaded as the README's GUI command loads it: the startup script run the way ParaView's
# GUI runs a --script, in the shell's namespace, which has no __file__.
startup = os.path.join(os.path.dirname(volreel.__file__), "paraview_startup.py")
shell = {"__name__": "__main__", "__builtins__": __builtins__}
with open(startup) as f:
    exec(compile(f.read(), startup, "exec"), shell)  # noqa: S102
reader = shell["VolreelReader"](FileName=container)
times = list(reader.TimestepValues)
assert len(times) == 6, times

scene = GetAnimationScene()
scene.UpdateAnimationUsingDataTimeSteps()
scene.AnimationTime = times[3]
reader.UpdatePipeline(times[3])
data = dsa.WrapDataObject(servermanager.Fetch(reader))
x, y, z = data.GetDimensions()
array = np.asarray(data.PointData.GetArray(0)).reshape(z, y, x)
expected = np.fromfile(decoded_file, dtype="<f4").reshape(z, y, x)
assert np.array_equal(array, expected), "time step 3 differs from volreel decode"
assert abs(data.GetInformation().Get(data.DATA_TIME_STEP()) - times[3]) < 1e-12

view = GetActiveViewOrCreate("RenderView")
view.ViewSize = [480, 360]
display = Show(reader, view)
display.SetRepresentationType("Volume")
ResetCamera(view)
Render(view)
SaveScreenshot(screenshot, view, ImageResolution=[480, 360])

# A coarser level: fewer voxels over the same box.
reader.Level = 0
reader.UpdatePipeline(times[3])
coarse = servermanager.Fetch(reader)
cx, cy, cz = coarse.GetDimensions()
assert cx * cy * cz < x * y * z, (coarse.GetDimensions(), (x, y, z))
# Its voxels average 2^d fine ones a side (d levels above the finest), centred among them.
import volreel  # noqa: E402
opened = volreel.open(container)
factor = 2 ** (opened.levels - 1)
assert opened.levels > 1, opened.levels
assert coarse.GetSpacing() == tuple(s * factor for s in opened.spacing), coarse.GetSpacing()
assert coarse.GetOrigin() == tuple(s * (factor - 1) / 2 for s in opened.spacing), coarse.GetOrigin()
bounds_fine, bounds_coarse = data.GetBounds(), coarse.GetBounds()
assert all(abs(a - b) <= max(1e-9, 0.02 * abs(a) + 1.0) for a, b in zip(bounds_fine, bounds_coarse))
print(f"paraview reader: time step 3 of {container} ({x}x{y}x{z}) equals volreel decode; "
      f"level 0 is {cx}x{cy}x{cz}; screenshot {screenshot}")
