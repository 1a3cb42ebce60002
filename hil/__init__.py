"""Tools around the loop, a subpackage each:

    cli       the ``boundswarm`` command line: its entry point, one module per subcommand
    campaign  campaigns of batch runs on Dask, and the seeded scenarios they draw
    sitl      the SITL launcher: a whole swarm on this machine, its processes, its report
    files     scenario files, robot profiles, run folders and their figures
    ground    ground-station tools: deploy bundles and certificates, the motion-capture
              bridge, the MCAP recorder, CAN inspection
"""
