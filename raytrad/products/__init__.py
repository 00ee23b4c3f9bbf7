"""Bake products of a solve: lightmaps, camera images and what is shown of the radiosity.

They compute arrays (texels, pixels, display colours) and write nothing; writing is
:mod:`raytrad.outputs`'. xatlas is imported only in :mod:`.atlas`.
"""
