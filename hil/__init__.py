"""Tools around the loop: the boundswarm CLI, scenario files, run folders, figures."""
