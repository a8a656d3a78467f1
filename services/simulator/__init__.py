"""The simulator service: a MuJoCo world standing in for the paper's Gazebo scene.

A small planar-base robot with a low forward camera, tennis balls (some scripted to move),
distractors and a settable main light; or several such robots in one world, each on its own
keys (:mod:`services.simulator.fleet`). The pure core is :mod:`services.simulator.sim`
(``Simulation``), its robots' bases :mod:`services.simulator.robot` and cameras
:mod:`services.simulator.sim_camera`; scenes are TOML files in ``services/simulator/scenarios/``.

Example::

    balltrack run simulator --set scenario=chase --set pacing=realtime
"""
