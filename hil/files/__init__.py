"""The files the tools read and write, and what they hold.

    scenario.py       scenario files (TOML): robots, formation, obstacles, parameters
    assignment.py     which robot takes which slot (a scenario's ``[formation] assign``)
    robot_profile.py  robot profiles: a robot's wheels and drivers in a file of its own
    run_folder.py     the run folder written by ``sim`` and ``sitl`` and read by ``report``
    figures.py        the paper's seven figures of a run folder (PNG)
    toml_text.py      TOML text of a plain document (a campaign's spec copy, a generated
                      scenario)
"""
