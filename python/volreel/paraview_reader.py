"""A ParaView reader for volreel containers (NAME.vreel folders).

Load it with the volreel Python package on PYTHONPATH: in pvpython `from volreel import pvplugin;
pvplugin.load(globals())`, in the GUI `paraview --script .../volreel/paraview_startup.py`. (ParaView's
own plugin loader — `--plugin`, Tools > Manage Plugins, `LoadPlugin` — works where ParaView's Python
has `inspect.getargspec`; Debian 12's ParaView 5.11 on Python 3.11 does not, which pvplugin works
around.) Then `VolreelReader(FileName="turbulence.vreel")` gives the container as image data
with its time steps (the animation toolbar plays them) and a Level property: -1 (the default) is
full resolution, 0 the root brick, each level doubling the resolution of the one before.
"""

from paraview.util.vtkAlgorithm import smdomain, smhint, smproperty, smproxy
from vtkmodules.numpy_interface import dataset_adapter as dsa
from vtkmodules.util.vtkAlgorithm import VTKPythonAlgorithmBase
from vtkmodules.vtkCommonDataModel import vtkImageData

import volreel


@smproxy.reader(name="VolreelReader", label="Volreel Reader",
                extensions="vreel", file_description="volreel containers")
class VolreelReader(VTKPythonAlgorithmBase):
    """Time steps of a volreel container as vtkImageData, decoded as `volreel decode` does."""

    def __init__(self):
        VTKPythonAlgorithmBase.__init__(self, nInputPorts=0, nOutputPorts=1,
                                        outputType="vtkImageData")
        self._file_name = None
        self._container = None
        self._level = -1

    def _open(self):
        if self._container is None:
            if not self._file_name:
                raise RuntimeError("VolreelReader: no FileName set")
            name = self._file_name
            if name.endswith("manifest.json"):  # the file inside the folder, as a file dialog gives
                name = name[: -len("manifest.json")].rstrip("/")
            self._container = volreel.open(name)
        return self._container

    def _level_index(self):
        c = self._open()
        level = self._level if self._level >= 0 else c.levels + self._level
        if not 0 <= level < c.levels:
            raise RuntimeError(f"VolreelReader: Level {self._level} is out of range: "
                               f"{c.location} has levels 0..{c.levels - 1} (-1: the finest)")
        return level

    @smproperty.stringvector(name="FileName")
    @smdomain.filelist()
    @smhint.filechooser(extensions="vreel", file_description="volreel containers")
    def SetFileName(self, name):
        if name != self._file_name:
            self._file_name = name
            self._container = None
            self.Modified()

    @smproperty.intvector(name="Level", default_values=-1)
    @smdomain.intrange(min=-1, max=20)
    def SetLevel(self, level):
        """Level of detail: -1 full resolution, 0 the root (a single brick)."""
        if level != self._level:
            self._level = level
            self.Modified()

    @smproperty.doublevector(name="TimestepValues", information_only="1",
                             si_class="vtkSITimeStepsProperty")
    def GetTimestepValues(self):
        return list(self._open().times) if self._file_name else None

    def _geometry(self):
        c = self._open()
        level = self._level_index()
        x, y, z = c.level_dims(level)
        # A level d above the finest averages 2^d fine voxels a side: its voxel i is centred on
        # fine voxel 2^d i + (2^d - 1) / 2 (the last one of an odd level holds its edge's copy).
        factor = 2 ** (c.levels - 1 - level)
        spacing = tuple(s * factor for s in c.spacing)
        origin = tuple(s * (factor - 1) / 2 for s in c.spacing)
        return level, (x, y, z), spacing, origin

    def RequestInformation(self, request, in_info, out_info):
        executive = self.GetExecutive()
        info = out_info.GetInformationObject(0)
        times = list(self._open().times)
        info.Remove(executive.TIME_STEPS())
        info.Remove(executive.TIME_RANGE())
        for t in times:
            info.Append(executive.TIME_STEPS(), t)
        info.Append(executive.TIME_RANGE(), times[0])
        info.Append(executive.TIME_RANGE(), times[-1])
        _, (x, y, z), spacing, origin = self._geometry()
        info.Set(executive.WHOLE_EXTENT(), 0, x - 1, 0, y - 1, 0, z - 1)
        info.Set(vtkImageData.SPACING(), *spacing)
        info.Set(vtkImageData.ORIGIN(), *origin)
        return 1

    def RequestData(self, request, in_info, out_info):
        c = self._open()
        executive = self.GetExecutive()
        info = out_info.GetInformationObject(0)
        times = list(c.times)
        step = 0
        if info.Has(executive.UPDATE_TIME_STEP()):
            wanted = info.Get(executive.UPDATE_TIME_STEP())
            step = min(range(len(times)), key=lambda i: abs(times[i] - wanted))
        level, (x, y, z), spacing, origin = self._geometry()
        volume = c.frame(step, level=level)  # [z, y, x]: x fastest, as VTK's point order
        output = dsa.WrapDataObject(vtkImageData.GetData(out_info, 0))
        output.SetDimensions(x, y, z)
        output.SetSpacing(*spacing)
        output.SetOrigin(*origin)
        output.PointData.append(volume.ravel(), c.variable or "value")
        output.PointData.SetActiveScalars(c.variable or "value")
        output.GetInformation().Set(output.DATA_TIME_STEP(), times[step])
        return 1
