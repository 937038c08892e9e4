# SPDX-License-Identifier: GPL-3.0-or-later
"""The one exception the engine raises for bad input.

Every message names the object and the problem, so the Blender layer can show it
as an operator report or a panel line without a traceback.
"""


class SceneInputError(ValueError):
    """Input the engine cannot work with, e.g. a reflector with no faces.

    ``object_name`` is the Blender object (or array) at fault; ``problem`` says what
    is wrong with it in words a user understands.
    """

    def __init__(self, object_name: str, problem: str):
        self.object_name = object_name
        self.problem = problem
        super().__init__(f"{object_name!r}: {problem}")
