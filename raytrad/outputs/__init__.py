"""Everything that writes a run's files: the radiosity PLY, lightmaps, camera images, the
baked glTF model, ``report.json``, convergence plots, comparison tables and checkpoints.

Each file is written atomically (:mod:`raytrad.formats.atomic`): a reader sees the old
file or the complete new one. matplotlib is imported only in :mod:`.plot`.
"""
