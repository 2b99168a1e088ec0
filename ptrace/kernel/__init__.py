"""The path loop, as a wavefront: paths live in structure-of-arrays waves (layout), and small
compiled stages run over queues of them (stages: camera rays, hits and the emission they find,
light found by shadow rays, per-pixel sums; trace: the backend's closest and any hit over a
queue; lighting: the light samples of every shading point, one kernel per light setup;
shading: one kernel per material kind, made only for the kinds a scene has). wavefront
drives them from Python, once per stage and bounce."""
