"""Open a marbles run in ParaView: spheres as glyphs scaled by their radius,
coloured by a point array, the walls as translucent surfaces, and optionally
the contact network.

  In the ParaView GUI:  paraview --script=scripts/paraview-view.py
                        (set MARBLES_OUT=OUTDIR first; MARBLES_COLOR=speed)
  Headless picture:     xvfb-run -a pvpython scripts/paraview-view.py OUTDIR \\
                            [--color-by ARRAY] [--contacts] [--screenshot FILE] \\
                            [--size W H] [--time T]

OUTDIR is a `marbles run` output folder (series.pvd, and walls.pvd /
contacts.pvd when the run wrote them).
"""
import argparse
import os
import sys

from paraview import simple as pv


def parse_arguments(argv):
    parser = argparse.ArgumentParser(description="show a marbles run in ParaView")
    parser.add_argument("outdir", nargs="?", default=os.environ.get("MARBLES_OUT", "out/demo"))
    parser.add_argument("--color-by", default=os.environ.get("MARBLES_COLOR", ""),
                        help="point array to colour by (default: speed, else radius)")
    parser.add_argument("--contacts", action="store_true", help="also show contacts.pvd as lines")
    parser.add_argument("--screenshot", help="save a picture of the last (or --time) frame and exit")
    parser.add_argument("--size", nargs=2, type=int, default=[960, 640], metavar=("W", "H"))
    parser.add_argument("--time", type=float, help="simulated time to show (default: the last frame)")
    return parser.parse_args(argv)


def show_run(args):
    """Builds the pipeline; returns (view, spheres reader, glyph)."""
    series = os.path.join(args.outdir, "series.pvd")
    if not os.path.exists(series):
        sys.exit("paraview-view: %s not found (run the scene with output.vtk first)" % series)
    view = pv.GetActiveViewOrCreate("RenderView")
    spheres = pv.PVDReader(registrationName="spheres", FileName=series)
    spheres.UpdatePipelineInformation()
    arrays = spheres.PointData.keys()
    if "radius" not in arrays:
        sys.exit("paraview-view: the frames have no radius array (add radius to output.fields)")
    color = args.color_by or ("speed" if "speed" in arrays else "radius")
    if color not in arrays:
        sys.exit("paraview-view: no point array '%s'; the frames have: %s" % (color, ", ".join(arrays)))

    # Sphere glyphs: the glyph source has radius 0.5, so a scale factor of 2
    # makes each sphere's radius its `radius` value.
    glyph = pv.Glyph(registrationName="glyphs", Input=spheres, GlyphType="Sphere")
    glyph.ScaleArray = ["POINTS", "radius"]
    glyph.ScaleFactor = 2.0
    glyph.GlyphMode = "All Points"
    glyph.GlyphType.ThetaResolution = 16
    glyph.GlyphType.PhiResolution = 12
    shown = pv.Show(glyph, view)

    walls_pvd = os.path.join(args.outdir, "walls.pvd")
    if os.path.exists(walls_pvd):
        walls = pv.PVDReader(registrationName="walls", FileName=walls_pvd)
        wall_display = pv.Show(walls, view)
        wall_display.ColorArrayName = ["POINTS", ""]  # a plain colour, not an array
        wall_display.DiffuseColor = [0.75, 0.75, 0.8]
        wall_display.Opacity = 0.3

    contacts_pvd = os.path.join(args.outdir, "contacts.pvd")
    if args.contacts and os.path.exists(contacts_pvd):
        contacts = pv.PVDReader(registrationName="contacts", FileName=contacts_pvd)
        contact_display = pv.Show(contacts, view)
        pv.ColorBy(contact_display, ("CELLS", "normal_force"))
        contact_display.LineWidth = 2.0

    times = spheres.TimestepValues
    times = [times] if isinstance(times, (int, float)) else list(times)
    scene = pv.GetAnimationScene()
    scene.UpdateAnimationUsingDataTimeSteps()
    view.ViewTime = args.time if args.time is not None else (times[-1] if times else 0.0)
    scene.AnimationTime = view.ViewTime
    glyph.UpdatePipeline(view.ViewTime)
    pv.ColorBy(shown, ("POINTS", color))
    shown.RescaleTransferFunctionToDataRange(False, True)  # the range of the frame shown
    shown.SetScalarBarVisibility(view, True)
    view.CameraPosition = [1, -1.5, 1]
    view.CameraFocalPoint = [0, 0, 0]
    view.CameraViewUp = [0, 0, 1]
    view.ResetCamera()
    return view, spheres, glyph


def main(argv):
    args = parse_arguments(argv)
    view, _, _ = show_run(args)
    if args.screenshot:
        view.ViewSize = args.size
        pv.Render(view)
        pv.SaveScreenshot(args.screenshot, view, ImageResolution=args.size)
        print("paraview-view: saved %s" % args.screenshot)
    else:
        pv.Render(view)


if __name__ == "__main__":
    main(sys.argv[1:] if len(sys.argv) > 1 or "MARBLES_OUT" not in os.environ else [])
