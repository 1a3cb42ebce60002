"""Ground-station tools: what runs beside a real swarm, not inside a simulation.

    deploy.py       bundles for robot computers and the ground station, from a swarm manifest
    certs.py        the swarm's certificate authority (mutual TLS between router and robots)
    mocap.py        the motion-capture bridge: pose fixes onto the swarm's Zenoh
    recorder.py     a swarm's Zenoh traffic into an MCAP file
    can_inspect.py  what a robot's CAN bus carries, decoded with the project's DBC
"""
