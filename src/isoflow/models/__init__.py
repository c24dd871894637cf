"""The physical systems of the paper, each a function returning ``(problem, initial_state)``."""

from .._errors import ParameterError as ParameterError
from .brockett import brockett as brockett
from .euler_sphere import coriolis_matrix as coriolis_matrix
from .euler_sphere import euler_sphere as euler_sphere
from .heisenberg_chain import heisenberg_chain as heisenberg_chain
from .hyperbolic_vortices import hyperbolic_vortices as hyperbolic_vortices
from .rigid_body import rigid_body as rigid_body
from .sphere_vortices import sphere_vortices as sphere_vortices
from .toda import jacobi_coefficients as jacobi_coefficients
from .toda import jacobi_matrix as jacobi_matrix
from .toda import off_band as off_band
from .toda import toda as toda

__all__: list[str] = [
    "ParameterError",
    "brockett",
    "coriolis_matrix",
    "euler_sphere",
    "heisenberg_chain",
    "hyperbolic_vortices",
    "jacobi_coefficients",
    "jacobi_matrix",
    "off_band",
    "rigid_body",
    "sphere_vortices",
    "toda",
]
