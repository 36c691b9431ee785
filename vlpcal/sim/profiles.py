"""Named simulation profiles: a nominal layout, how far the real install strays from it, and how
frames look. Every value says where it comes from (``Profile.sources``).

- ``paper-2024``: the paper's lab (Table 2, section 3): three 160 × 120 px OV2640 cameras 2.3 m
  above a 3.6 × 1.8 m floor, C1 and C3 1.2 m apart with C2 in the middle, a careful install.
- ``cheap-wide``: four wide-angle (77°) cameras with strong barrel distortion in a 2 × 2 grid
  under a 2.8 m ceiling, hung with 1–2° of tilt, a floor reflection and a lamp in view.
- ``qvga``: the paper's geometry with 320 × 240 px cameras (the OV2640's next mode).

:func:`profile_of_deployment` makes a profile of any deployment file (``vlpcal simulate -d``).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..geometry import NADIR, PAPER_F, Camera, paper_rig
from .scene import Appearance, InstallErrors, Profile

DEG = math.pi / 180.0

PAPER_SOURCES = {
    "layout": "paper 3.1/3.3: C1 and C3 form the first pair, C2 is 'placed in the middle'; one "
              "camera sees 240 cm, a pair shares 120 × 180 cm (Table 2's experimental area), so "
              "C1–C3 = 1.2 m at x = 1.2 and 2.4 m, C2 at 1.8 m, all on y = 0.9 m, 2.3 m up",
    "f": "240 cm of floor across 160 px from 2.3 m: f = 160 · 2.3 / 2.4 ≈ 153.3 px "
         "(the 4.8 mm datasheet lens would give ~218 px; calibrate f)",
    "aspect": "measured: the ESP32 driver scales a 400 × 296 window to 160 × 120, pixels "
              "~1.35 % non-square",
    "install errors": "fitted to the paper's results, not to a datasheet: its pair errors of "
                      "~1.5 cm in z on a 0.6 m baseline leave room for only ~0.2 px of "
                      "disparity error, so the lab's scaling K (section 2.2) must have been "
                      "measured per camera, absorbing focal length and principal point; "
                      "benchmarks/paper.py shows how close this lands",
    "position, height": "±2 mm: cameras placed with care on a lab rig",
    "tilt": "0.05° per axis (paper 3.3: 'levelling the camera is also challenging', but 0.5° "
            "alone would cost 4 cm of depth; the published errors rule that out)",
    "yaw": "0.15°: cameras squared to the rig",
    "focal, principal": "0.5 %, 0.15 px: what is left after the per-camera scaling K",
    "k1, k2": "paper 3.3: distortion is not corrected; k1 = −0.02 ± 0.01: the published "
              "errors allow no more (uncorrected, k1 = −0.15 costs 3 cm of depth)",
    "led_peak": "the paper thresholds its spots and reports no saturation handling: a bright LED "
                "that reaches ~255 under the camera and fades toward the edges",
    "psf_sigma": "0.75 px: a 160 × 120 image binned from a 400 × 296 window blurs ~2.5 sensor "
                 "pixels into one",
    "psf_growth, vignetting": "cheap lens: blur grows and brightness falls toward the corners "
                              "(paper 3.4.2: accuracy degrades with the angle of view)",
    "noise": "OV2640 read noise ~2 DN at these gains; shot noise 0.08 DN² per DN",
    "jpeg_quality": "ESP32-CAM's default JPEG quality setting 12 ≈ libjpeg quality 70",
    "reflection": "none: the LED faces up and a matte lab floor shows no image of it",
    "tape": "survey positions by tape measure: ±3 mm per axis",
}


#: the paper's lab, chosen so that the paper's own pipeline on simulated frames lands near its
#: Tables 3–4 (benchmarks/paper.py). Errors this small mean the lab in effect calibrated its
#: cameras: section 2.2's scaling coefficients K1, K2 turn pixels into floor metres and, set from
#: measurements, absorb the focal length and principal point; a 2 mm error in the 0.6 m baseline
#: alone already costs ~0.8 cm of depth.
PAPER_ERRORS = InstallErrors(position=0.002, height=0.002, tilt=0.05 * DEG, yaw=0.15 * DEG,
                             focal=0.005, aspect=0.0135, principal=0.15, k1=(-0.02, 0.01),
                             k2=(0.0, 0.005), tangential=0.0002)


def paper_2024() -> Profile:
    return Profile(
        name="paper-2024",
        description="the paper's lab: 3 OV2640 cameras at 160 × 120 px, 2.3 m up, C1–C3 1.2 m "
                    "apart with C2 between, over a 3.6 × 1.8 m floor; a careful install",
        nominal=tuple(paper_rig()),
        room=((0.0, 0.0), (3.6, 0.0), (3.6, 1.8), (0.0, 1.8)),
        ceiling_height=2.3,
        errors=PAPER_ERRORS,
        look=Appearance(led_peak=300.0, psf_sigma=0.75, psf_growth=0.5, vignetting=0.5,
                        background=20.0, read_noise=2.0, shot_gain=0.08, jpeg_quality=70),
        tape=0.003,
        sources=PAPER_SOURCES,
    )


def _wide_camera(cid: str, x: float, y: float, z: float) -> Camera:
    return Camera(cid, 160, 120, 100.0, 100.0, 79.5, 59.5, (0, 0, 0, 0, 0), (x, y, z), NADIR)


def cheap_wide() -> Profile:
    cams = tuple(_wide_camera(f"C{k + 1}", x, y, 2.8)
                 for k, (x, y) in enumerate([(1.5, 1.3), (3.5, 1.3), (1.5, 2.7), (3.5, 2.7)]))
    return Profile(
        name="cheap-wide",
        description="4 wide-angle (77° across) 160 × 120 px cameras in a 2 × 2 grid under a "
                    "2.8 m ceiling, 5 × 4 m room; strong barrel distortion, 1–2° of tilt, a "
                    "floor reflection and a lamp",
        nominal=cams,
        room=((0.0, 0.0), (5.0, 0.0), (5.0, 4.0), (0.0, 4.0)),
        ceiling_height=2.8,
        errors=InstallErrors(position=0.02, height=0.015, tilt=1.2 * DEG, yaw=1.0 * DEG,
                             focal=0.03, aspect=0.0135, principal=4.0, k1=(-0.28, 0.04),
                             k2=(0.08, 0.02), tangential=0.001),
        look=Appearance(led_peak=500.0, reference_distance=2.8, psf_sigma=0.9, psf_growth=0.6,
                        vignetting=0.6, background=24.0, gradient=(0.05, -0.03),
                        read_noise=2.5, shot_gain=0.1, jpeg_quality=60, reflection=0.25,
                        reflection_blur=2.0, lamp=(4.6, 3.7, 0.0, 320.0, 5.0)),
        tape=0.005,
        sources={
            "f": "77° across 160 px: f = 80 / tan(38.7°) ≈ 100 px (a '120° class' M12 lens "
                 "cropped by the sensor)",
            "k1, k2": "cheap wide lenses: k1 ≈ −0.1 to −0.3 (OpenCV sample −0.27); "
                      "k2 +0.08 as in OpenCV's sample",
            "tilt": "1–2° of tilt when hung without care: 1.2° per axis "
                    "(1.5° in total on average, 1.7° RMS)",
            "position, height, yaw": "hung from a ceiling grid: ±2 cm, ±1.5 cm, ±1°",
            "principal": "cheap lenses: 1–7 % of the image size: 4 px",
            "led_peak, psf, vignetting": "a bright LED (500 DN on the axis from 2.8 m, so that "
                                         "it still shows ~50 DN in the corners of a 77° view); "
                                         "blur 1.6× and vignetting 60 % at the corners",
            "reflection, lamp": "a polished floor mirroring 25 % of the LED (a stress test: an "
                                "up-facing LED sends little light down) and a desk lamp in a "
                                "corner: a 20 cm "
                                "shade 2 m from the camera is ~10 px across at f = 100 px "
                                "(σ 5 px), bright enough to saturate",
            "tape": "a larger room surveyed by tape: ±5 mm",
        },
    )


def qvga() -> Profile:
    cams = tuple(Camera(c.id, 320, 240, 2 * PAPER_F, 2 * PAPER_F, 159.5, 119.5, c.dist,
                        c.position, c.rotation) for c in paper_rig())
    base = paper_2024()
    return Profile(
        name="qvga",
        description="the paper's geometry and install at 320 × 240 px (the OV2640's QVGA mode)",
        nominal=cams,
        room=base.room,
        ceiling_height=base.ceiling_height,
        errors=replace(PAPER_ERRORS, principal=2 * PAPER_ERRORS.principal),
        look=Appearance(led_peak=300.0, psf_sigma=1.2, psf_growth=0.5, vignetting=0.5,
                        background=20.0, read_noise=2.0, shot_gain=0.08, jpeg_quality=70),
        tape=0.003,
        sources={**PAPER_SOURCES,
                 "f": "twice the paper's: 306.6 px (same lens, twice the pixels)",
                 "focal, principal": "0.5 %, 0.3 px: the paper's install, in twice the pixels",
                 "psf_sigma": "1.2 px: the same optical blur over twice the pixels, less "
                              "binning (400 × 296 → 320 × 240)"},
    )


PROFILES = {"paper-2024": paper_2024, "cheap-wide": cheap_wide, "qvga": qvga}

#: px: cameras at least this wide look like ``qvga``'s (a wider blur in pixels), narrower ones
#: like ``paper-2024``'s
QVGA_LOOK_WIDTH = 320


def profile_of_deployment(dep, errors: InstallErrors) -> Profile:
    """Any deployment as a simulation profile: its cameras as the nominal install (any number,
    any room, its keep-outs kept), hung with ``errors`` — ``vlpcal simulate -d`` passes
    :data:`vlpcal.demo.DEMO_ERRORS`, the demo's careful install by hand (that module, above
    this one, owns the numbers). The rest is the closest named profile's, so that a site
    looks like one the benchmarks measured:

    - the frames look like ``paper-2024``'s (the paper's 160 × 120 px OV2640), or ``qvga``'s
      when the cameras (their median width) are :data:`QVGA_LOOK_WIDTH` px wide or wider,
      except that the LED is as bright under the cameras as the paper's under its own
      (``reference_distance`` = the cameras' median height), whatever the ceiling — someone
      hanging cameras higher picks an LED that the cameras still see;
    - the principal-point error scales with the image width from ``errors``' (as ``qvga``
      scales ``paper-2024``'s), since ``errors`` counts pixels of a 160 px wide image;
    - the tape is ``paper-2024``'s (±3 mm).
    """
    cams = tuple(dep.cameras)
    width = float(np.median([c.width for c in cams]))
    wide = width >= QVGA_LOOK_WIDTH
    base = qvga() if wide else paper_2024()
    height = float(np.median([c.position[2] for c in cams]))
    look = replace(base.look, reference_distance=max(height, 0.5))
    errors = replace(errors, principal=errors.principal * width / 160.0)
    xs, ys = np.asarray(dep.room, float).T
    return Profile(
        name=dep.name,
        description=f"{len(cams)} cameras of the deployment over a "
                    f"{np.ptp(xs):.1f} × {np.ptp(ys):.1f} m floor under a "
                    f"{dep.ceiling_height:g} m ceiling"
                    + (f", {len(dep.keep_out)} keep-out{'s' * (len(dep.keep_out) > 1)}"
                       if dep.keep_out else "") + ", hung with a careful install's errors",
        nominal=cams,
        room=tuple(tuple(map(float, xy)) for xy in dep.room),
        ceiling_height=float(dep.ceiling_height),
        errors=errors,
        look=look,
        tape=base.tape,
        keep_out=tuple(tuple(tuple(map(float, xy)) for xy in k) for k in dep.keep_out),
        sources={
            "layout": "the deployment file: its cameras as planned (nominal.yaml), its room "
                      "and keep-outs",
            "install errors": "a careful install by hand (vlpcal demo's): "
                              f"±{errors.position * 1000:.0f} mm across, "
                              f"±{errors.height * 1000:.0f} mm in height, "
                              f"{math.degrees(errors.tilt):.2g}° of tilt per axis, "
                              f"{math.degrees(errors.yaw):.2g}° of yaw, focal length "
                              f"±{errors.focal * 100:.2g} %, principal point "
                              f"±{errors.principal:.2g} px (at {width:.0f} px wide), k1 "
                              f"{errors.k1[0]:+g} ± {errors.k1[1]:g}",
            "look": (f"qvga's (the cameras are {width:.0f} px wide: ≥ {QVGA_LOOK_WIDTH} px)"
                     if wide else f"paper-2024's (the cameras are {width:.0f} px wide: "
                                  f"< {QVGA_LOOK_WIDTH} px)"),
            "led_peak": f"{look.led_peak:g} DN under a camera {look.reference_distance:.2f} m "
                        "up (the cameras' median height): as bright as the paper's LED under "
                        "its cameras",
            "tape": "paper-2024's: ±3 mm per axis",
        },
    )


def get_profile(name: str) -> Profile:
    """A profile by name; ``ValueError`` lists the known names."""
    try:
        return PROFILES[name]()
    except KeyError:
        raise ValueError(f"unknown simulation profile {name!r}; expected one of "
                         f"{', '.join(PROFILES)}") from None
