"""The links: CAN to the motor drivers, Zenoh between agents, MAVLink to ground stations."""
