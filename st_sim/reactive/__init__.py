"""Reactive pedestrians of a replay: the people of a recording, who walk their logged paths until a robot comes their
way, then leave their log round it (slowing, waiting or stepping aside with room that grows with the robot's speed)
and rejoin it. ``reactive`` steps N crowds at once; ``routes``, ``candidates``, ``choosing``, ``detour`` and
``footprint`` are the logged routes, the places a pedestrian may step to, the choice among them, the way round the
robot and the bodies; ``reaction`` holds the reaction fitted on people round a vehicle (``reaction_fit.json``,
``spread_fit.json``); ``compiled`` the same step compiled with numba. It is a model of people, below the
environments: ``envs.replay_env`` puts it in a replay with ``pedestrians="reactive"``.
"""
