"""The embedded default dataset: a rendered stand-in for the real GreenHouse sequence.

``make_greenhouse(folder)`` renders a camera run through a 3D greenhouse hall (a plant factory
like the one of the real set) and writes it as a sequence folder (the files: see ``make``; the
contract: ``greenloop.datasets.sequence``); ``python -m greenloop data synthetic OUT`` is its
command line (``make synthetic``). Its parts, each importing only parts listed above it:

    hall      the hall frame (x across, y up, z along, metres), its fixed layout, the seed check
    camera    the D435i colour intrinsics scaled to the image size, camera.yaml
    route     the camera's route through the aisles: poses, the same path for any frame count
    textures  the floor, roof and wall textures and their atlas
    plants    the plants on the beds as 3D leaf ellipses
    scene     ``build_scene``: the hall's objects as polygons, with the plants and the textures
    render    ``render_frame``: one clean frame (colour, depth) by a painter's algorithm
    sensor    lighting drift, flicker, blur, noise and D435i-like depth on a clean frame
    make      ``make_greenhouse``: frames over a worker pool, the metadata files
    days      the greenhouse over days: the larger hall ``DaysHall``, a day's record ``Day``,
              the days' design ``design_days``, a day's route ``day_route``
    dayscene  ``build_day_scene``: the larger hall on one day (light, growth, harvest, objects)
    daysmake  ``make_greenhouse_days``: every day's sequence folder and the multi-day stream
              (``python -m greenloop data greenhouse-days``), with wheel odometry
              (``greenloop.datasets.odometry``)

Public: ``make_greenhouse``, ``make_greenhouse_days``, ``Day``, ``DaysHall``, ``design_days``,
``day_route``, ``build_day_scene``, ``route``, ``route_world``,
``route_waypoints``, ``route_length``, ``camera_intrinsics``, ``write_camera_yaml``,
``build_scene`` (a ``Scene``), ``render_frame``, and the limits ``DEFAULT_FRAMES``,
``MIN_FRAMES``, ``DEFAULT_SIZE``, ``MIN_SIZE``, ``DEFAULT_NOISE``, ``MIN_DEPTH``, ``MAX_DEPTH``.
"""
from greenloop.datasets.synthetic.camera import (DEFAULT_SIZE, MIN_SIZE, camera_intrinsics,
                                                 write_camera_yaml)
from greenloop.datasets.synthetic.days import Day, day_route, DaysHall, design_days
from greenloop.datasets.synthetic.dayscene import build_day_scene
from greenloop.datasets.synthetic.daysmake import make_greenhouse_days
from greenloop.datasets.synthetic.make import make_greenhouse
from greenloop.datasets.synthetic.render import render_frame
from greenloop.datasets.synthetic.route import (DEFAULT_FRAMES, MIN_FRAMES, route, route_length,
                                                route_waypoints, route_world)
from greenloop.datasets.synthetic.scene import build_scene, Scene
from greenloop.datasets.synthetic.sensor import DEFAULT_NOISE, MAX_DEPTH, MIN_DEPTH

__all__ = ["make_greenhouse", "make_greenhouse_days", "Day", "DaysHall", "design_days", "day_route",
           "build_day_scene", "route", "route_world", "route_waypoints", "route_length",
           "camera_intrinsics", "write_camera_yaml", "build_scene", "Scene", "render_frame",
           "DEFAULT_FRAMES", "MIN_FRAMES", "DEFAULT_SIZE", "MIN_SIZE", "DEFAULT_NOISE",
           "MIN_DEPTH", "MAX_DEPTH"]
