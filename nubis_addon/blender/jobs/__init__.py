"""Work that makes files and pictures, shared by the buttons and the command line: renders, bakes and
Cycles renders (pipeline), what a bake reads when it starts (snapshot), the comparison against Cycles
(comparison, with reference: Cycles' noise, and sun_air: the sun through the air in Cycles), the viewport
headless and the benchmark (preview), sequences and Dask farms (farm), and the one job that runs in steps
while the artist keeps working (work).

May import: core/, render/, blender/host/, blender/scene/."""
