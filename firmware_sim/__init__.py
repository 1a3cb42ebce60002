"""The SITL plant: robot motion, the world (obstacles, sensing, ground truth, metrics) and
the batch simulator."""
