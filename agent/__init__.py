"""What runs on a robot computer: the bounded formation control law (pure), formation
references, diff-drive kinematics, odometry and neighbour extrapolation."""
