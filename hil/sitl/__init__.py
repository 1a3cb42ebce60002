"""The SITL launcher: a whole swarm on this machine in wall-clock time (``boundswarm sitl``).

    swarm.py           the one-command SITL swarm: router, plants, agents, recording, watch
    launch.py          how it hosts the data path (the Zenoh router in a process of its own)
                       and lays the agents out over processes
    processes.py       its child processes, started, watched and ended by PID
    report.py          the recording turned into the run data and metrics that ``sim`` writes
    mavlink_router.py  the agents behind one ground-station MAVLink port
    host_cpu.py        the CPU the machine really had: steal, busy share, real-time cap
"""
