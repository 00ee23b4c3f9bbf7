"""Byte-level file formats that know only arrays: EXR and PNG images (OpenImageIO), the
radiosity PLY, the GLB container, the checkpoint file, and atomic writes under them all.

Nothing here knows a :class:`~raytrad.scene.Scene` or a solve: every function takes and
returns numpy arrays, bytes and plain values. Bad bytes raise ``ValueError`` (callers that
know the file turn it into a one-line :class:`~raytrad.errors.SceneError`), or a
``SceneError`` naming the file where the function is given its path.
"""
