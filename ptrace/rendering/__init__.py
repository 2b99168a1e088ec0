"""The render job around the kernel: validated settings, the render() call, the tiles and
passes a job is cut into, the executors that run them (in process, or on Dask) and the timing
of their phases."""
