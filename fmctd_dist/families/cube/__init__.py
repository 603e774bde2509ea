"""The robot-arm cube family (OGBench cube-single/-double/-triple): env, play data, the arm's scripts and
learned policy, object-wise actions and the cube value, the episode, its failure analysis and figures."""
