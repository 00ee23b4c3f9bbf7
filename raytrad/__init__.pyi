# Types of the names raytrad/__init__.py imports lazily (tests/test_public_api.py keeps
# this list equal to raytrad.__all__).
from raytrad.api import Prepared as Prepared
from raytrad.api import RenderOutcome as RenderOutcome
from raytrad.api import RenderProgress as RenderProgress
from raytrad.api import compare as compare
from raytrad.api import comparison_table as comparison_table
from raytrad.api import estimate_error as estimate_error
from raytrad.api import load as load
from raytrad.api import make_reference as make_reference
from raytrad.api import outputs_current as outputs_current
from raytrad.api import prepare as prepare
from raytrad.api import refine as refine
from raytrad.api import render as render
from raytrad.api import solve as solve
from raytrad.api import solve_scene as solve_scene
from raytrad.api import verify_outputs as verify_outputs
from raytrad.api import write as write
from raytrad.batch import DaskRunner as DaskRunner
from raytrad.batch import Job as Job
from raytrad.batch import JobResult as JobResult
from raytrad.batch import LocalPool as LocalPool
from raytrad.batch import bake as bake
from raytrad.batch import read_manifest as read_manifest
from raytrad.batch import run_job as run_job
from raytrad.core.solver import SolveResult as SolveResult
from raytrad.core.solver import SolverState as SolverState
from raytrad.errors import RaytradError as RaytradError
from raytrad.errors import SceneError as SceneError
from raytrad.errors import SettingsError as SettingsError
from raytrad.errors import SolverError as SolverError
from raytrad.scene import Scene as Scene
from raytrad.scenefiles import SceneFile as SceneFile
from raytrad.settings import Camera as Camera
from raytrad.settings import ImageSettings as ImageSettings
from raytrad.settings import LightmapSettings as LightmapSettings
from raytrad.settings import MeshSettings as MeshSettings
from raytrad.settings import RefineSettings as RefineSettings
from raytrad.settings import RenderSettings as RenderSettings
from raytrad.settings import SolveSettings as SolveSettings

__version__: str
__all__: list[str]
