"""The tasks a scene can run, in one table: name -> ``"module:Class"``, imported only when a scene names it.

A scene's ``task`` is a name of :data:`TASKS`, or ``"module:Class"`` for a task that lives outside this package
(``task = "my_lab.wipe:Wipe"``, its module importable where the trials run). Adding a task to the package: its
module in ``behaviours/`` and one line here (docs/your_task.md).
"""

from __future__ import annotations

import importlib
import os
import sys
from pathlib import Path

from tactile_manip.behaviours.task import Task

TASKS: dict[str, str] = {
    "reorient": "tactile_manip.behaviours.reorient:Reorient",
    "place": "tactile_manip.behaviours.place:Place",
    "grip": "tactile_manip.behaviours.grip:Grip",
}
DEFAULT_TASK = "reorient"  # the task of a scene that names none, and of trial records written before records named it


def task_class(ref: str) -> type[Task]:
    """The :class:`~tactile_manip.behaviours.task.Task` subclass that ``ref`` names (a name of :data:`TASKS`, or
    ``"module:Class"``). A module not found on ``sys.path`` is looked for in the working directory too (the
    ``tactile-manip`` script does not put it on the path, ``python -m`` does).

    Raises:
        ValueError: ``ref`` names no task, its module cannot be imported, or it is not a Task subclass.
    """
    if not isinstance(ref, str) or not ref:
        raise ValueError(f"task must be one of {', '.join(TASKS)} or 'module:Class', got {ref!r}")
    target = TASKS.get(ref, ref)
    module_name, sep, attr = target.partition(":")
    if not (module_name and sep and attr):
        raise ValueError(f"task must be one of {', '.join(TASKS)} or 'module:Class', got {ref!r}")
    module = _import(module_name, ref)
    cls = getattr(module, attr, None)
    if not (isinstance(cls, type) and issubclass(cls, Task)):
        raise ValueError(f"task {ref!r}: {module_name} has no Task subclass called {attr} "
                         "(a task is a subclass of tactile_manip.behaviours.task.Task)")
    if not isinstance(getattr(cls, "name", None), str) or not cls.name.isidentifier():
        raise ValueError(f"task {ref!r}: {attr}.name must be a word (letters, digits, _), got "
                         f"{getattr(cls, 'name', None)!r}")
    return cls


def task_root(cls: type[Task]) -> str | None:
    """The folder to put on a worker's ``sys.path`` so that it imports ``cls``'s module (None for the package's
    own tasks, and for a module that has no file)."""
    top = cls.__module__.split(".")[0]
    if top == __name__.split(".")[0]:
        return None
    module = sys.modules.get(top)
    file = getattr(module, "__file__", None)
    if file:
        path = Path(file).resolve()
        return str(path.parent.parent if path.name == "__init__.py" else path.parent)
    folders = list(getattr(module, "__path__", []))  # a folder without __init__.py (a namespace package)
    return str(Path(folders[0]).resolve().parent) if folders else None


def _import(module_name: str, ref: str):
    try:
        return importlib.import_module(module_name)
    except ModuleNotFoundError as e:
        top = module_name.split(".")[0]
        here = os.getcwd()
        in_here = (Path(here) / top).is_dir() or (Path(here) / f"{top}.py").is_file()
        if e.name != top or here in sys.path or not in_here:
            raise ValueError(f"task {ref!r}: cannot import {module_name} ({e}); install it, or run from the "
                             "folder that holds it") from None
        sys.path.insert(0, here)  # the console script leaves the working directory off the path
        try:
            return importlib.import_module(module_name)
        except ImportError as e2:
            raise ValueError(f"task {ref!r}: cannot import {module_name} ({e2})") from None
    except ImportError as e:
        raise ValueError(f"task {ref!r}: cannot import {module_name} ({e})") from None
