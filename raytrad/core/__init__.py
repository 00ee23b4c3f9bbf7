"""The radiosity core: repair, meshing, visibility, form-factor kernels and engine, the
pipeline that turns a scene and mesh settings into a solvable problem, the solvers, their
convergence log and reference solutions. Nothing here reads or writes a file.

==========================  =================================================
module                      holds
==========================  =================================================
:mod:`.repair`              T-junctions, duplicate and inside-out faces
:mod:`.refine`              vertex merge, conforming refinement, clusters
:mod:`.mesh`                receivers, patches, sub-areas (:class:`RadiosityMesh`)
:mod:`.visibility`          the embreex adapter (:class:`Occluder`)
:mod:`.kernels`             closed-form point-to-area form factors
:mod:`.contour`             a patch's exact factor from its outline
:mod:`.formfactor`          the vertex-to-patch form-factor engine and balancing
:mod:`.pipeline`            scene + mesh settings -> :class:`Prepared`
:mod:`.solver`              shooting methods (the registry) and the solve
:mod:`.convergence`         error log: estimate, bound, true error, ETA
:mod:`.reference`           dense, analytic and converged references
:mod:`.pathtrace`           an independent Monte Carlo reference
==========================  =================================================
"""
