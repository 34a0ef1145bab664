"""Grasp quality: the paper's measures (polygon shape, force balance), the Ferrari-Canny
epsilon, and the fitness of a swarm, with their compiled kernels."""
