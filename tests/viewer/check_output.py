"""pvpython check of a marbles output folder, the way a ParaView user opens it.

  xvfb-run -a pvpython tests/viewer/check_output.py OUTDIR PARAVIEW_VIEW_PY MATERIALS

Checks, through ParaView's own readers: every time step of series.pvd (the
times the .pvd lists), the point arrays at each, the material names in the
field data, the walls (walls.pvd: surfaces with wall and material), the
contacts (contacts.pvd: lines with normal_force); then draws the spheres as
glyphs with scripts/paraview-view.py and checks the picture is not blank.
Exits 1 with the first failure.
"""
import importlib.util
import os
import sys
import xml.etree.ElementTree as ET

from paraview import servermanager
from paraview import simple as pv
from vtkmodules.vtkIOImage import vtkPNGReader


def fail(message):
    print("viewer: FAILED: " + message)
    sys.exit(1)


def listed_times(pvd):
    return [float(d.get("timestep")) for d in ET.parse(pvd).getroot().iter("DataSet")]


def fetch(reader, time):
    reader.UpdatePipeline(time)
    data = servermanager.Fetch(reader)
    if data.IsA("vtkMultiBlockDataSet"):
        data = data.GetBlock(0)
    return data


def strings(field_data, name):
    array = field_data.GetAbstractArray(name)
    if array is None:
        return None
    return [array.GetValue(i) for i in range(array.GetNumberOfValues())]


outdir, view_script, materials = sys.argv[1], sys.argv[2], sys.argv[3].split(",")

# Spheres: every time step, every array, the material names.
series = os.path.join(outdir, "series.pvd")
times = listed_times(series)
spheres = pv.PVDReader(FileName=series)
spheres.UpdatePipelineInformation()
steps = spheres.TimestepValues
steps = [steps] if isinstance(steps, (int, float)) else list(steps)
if len(steps) != len(times) or any(abs(a - b) > 1e-12 for a, b in zip(steps, times)):
    fail("ParaView sees time steps %s, series.pvd lists %s" % (steps, times))
expected_arrays = {"radius", "velocity", "angular_velocity", "id", "material", "speed", "contacts"}
points = None
for t in times:
    data = fetch(spheres, t)
    names = {data.GetPointData().GetArrayName(i) for i in range(data.GetPointData().GetNumberOfArrays())}
    if not expected_arrays <= names:
        fail("frame at t=%g lacks point arrays %s" % (t, sorted(expected_arrays - names)))
    if points is None:
        points = data.GetNumberOfPoints()
    if data.GetNumberOfPoints() != points or points == 0:
        fail("frame at t=%g has %d points, the first had %d" % (t, data.GetNumberOfPoints(), points))
    if abs(data.GetFieldData().GetArray("TimeValue").GetValue(0) - t) > 1e-12:
        fail("frame at t=%g holds TimeValue %g" % (t, data.GetFieldData().GetArray("TimeValue").GetValue(0)))
    if strings(data.GetFieldData(), "material_names") != materials:
        fail("material names %s, expected %s" % (strings(data.GetFieldData(), "material_names"), materials))

# Walls: surfaces at every time step.
walls_pvd = os.path.join(outdir, "walls.pvd")
if listed_times(walls_pvd) != times:
    fail("walls.pvd lists other times than series.pvd")
walls = pv.PVDReader(FileName=walls_pvd)
walls.UpdatePipelineInformation()
for t in times:
    data = fetch(walls, t)
    if data.GetNumberOfPolys() == 0 or data.GetCellData().GetArray("material") is None:
        fail("walls at t=%g: %d polygons, material array %s" % (t, data.GetNumberOfPolys(),
                                                                data.GetCellData().GetArray("material")))

# Contacts: lines with forces.
contacts_pvd = os.path.join(outdir, "contacts.pvd")
contacts = pv.PVDReader(FileName=contacts_pvd)
contacts.UpdatePipelineInformation()
last = fetch(contacts, listed_times(contacts_pvd)[-1])
if last.GetNumberOfLines() == 0 or last.GetCellData().GetArray("normal_force") is None:
    fail("the last contact frame has %d lines" % last.GetNumberOfLines())

# The picture: spheres as glyphs, coloured by speed, walls shown.
spec = importlib.util.spec_from_file_location("paraview_view", view_script)
view_module = importlib.util.module_from_spec(spec)
spec.loader.exec_module(view_module)
picture = os.path.join(outdir, "paraview.png")
view_module.main([outdir, "--color-by", "speed", "--contacts", "--screenshot", picture, "--size", "640", "480"])
png = vtkPNGReader()
png.SetFileName(picture)
png.Update()
image = png.GetOutput()
scalars = image.GetPointData().GetScalars()
width, height, _ = image.GetDimensions()
background = scalars.GetTuple(0)
colours, differing = set(), 0
for i in range(0, width * height, 7):
    pixel = scalars.GetTuple(i)
    colours.add(pixel)
    differing += pixel != background
if len(colours) < 20 or differing < 0.02 * width * height / 7:
    fail("the picture looks blank: %d colours, %d of %d sampled pixels differ from the background"
         % (len(colours), differing, width * height // 7))
print("viewer: ok (%d time steps, %d spheres, walls and contacts read by ParaView; picture with %d colours)"
      % (len(times), points, len(colours)))
