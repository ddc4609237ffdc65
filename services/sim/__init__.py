"""The digital twin: table, object, gripper and a D435-like camera, with real-world errors (docs/sim.md).

Public entry points: ``catalogue.load_object``, ``render.RenderScene`` / ``render.render``,
``sensor_model.D435Noise``, ``world.World``, ``profiles.get_profile`` / ``profiles.hand_turn`` and
``scenario.simulated_views`` / ``scenario.write_session``. Importing this package imports nothing heavy.
"""
