"""
Output paths of the commands: checked before any work, written under a temporary name.

``replay BAG -o BAG`` used to destroy its input (also through a symlink or a hard link) and
``view BAG -o BAG`` overwrote a bag with an .rrd; a command stopped halfway left a file
that looked complete. So every command checks each output first (its folder exists and
can be written, it is none of the command's inputs: the same file by path, symlink or
hard link, or inside an input directory, or holding one) and writes it in a hidden
staging folder beside it, moved onto the final name only when the command has finished.
Live recordings (``record``, the node's ``record_path``) are written in place instead: a
killed one keeps every finished chunk under its own name (``cvc-balance reindex``).
"""

from contextlib import contextmanager
import os
from pathlib import Path
import shutil
import tempfile


class OutputError(ValueError):
    """An output that must not or cannot be written; ``str()`` says why in one line."""


def check_output(path, inputs=()):
    """
    Check that ``path`` may be written by a command reading ``inputs``; raise OutputError.

    ``inputs``: paths (files or directories; None entries skipped). Existing outputs are
    fine (they are replaced at the end), except a directory where a file is asked.
    """
    output = Path(path)
    folder = output.parent
    if not folder.is_dir():
        raise OutputError(f'{path}: folder {folder} does not exist')
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputError(f'{path}: folder {folder} cannot be written')
    target = output.resolve()
    for source in inputs:
        if source is None or not Path(source).exists():
            continue                    # reading it will say what is wrong
        origin = Path(source).resolve()
        same = target == origin or (output.exists() and os.path.samefile(output, source))
        if same or origin in target.parents or target in origin.parents:
            raise OutputError(f'{path}: is (or holds, or is in) the input {source}; not '
                              'written over it (give another output name)')


@contextmanager
def replaced_when_done(path):
    """
    Yield a temporary path with ``path``'s name; move it onto ``path`` if the block succeeds.

    The temporary lies in a hidden staging folder beside ``path`` (same file system: the
    move is a rename). An existing ``path`` is replaced (a directory: removed first); on
    an error the staging folder goes and ``path`` is left as it was.
    """
    output = Path(path)
    staging = Path(tempfile.mkdtemp(prefix=f'.{output.name}.', suffix='.partial',
                                    dir=output.parent))
    try:
        temporary = staging / output.name
        yield temporary
        if not temporary.exists():
            return                      # nothing was written (the command chose not to)
        if output.is_dir() and not output.is_symlink():
            shutil.rmtree(output)
        os.replace(temporary, output)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


@contextmanager
def moved_into_when_done(directory):
    """
    Yield a staging folder; move what it holds into ``directory`` if the block succeeds.

    For commands that write several files into a folder the user names (a report): the
    folder is made if absent, files of the same names in it are replaced, others left.
    """
    directory = Path(directory)
    staging = Path(tempfile.mkdtemp(prefix=f'.{directory.name}.', suffix='.partial',
                                    dir=directory.parent))
    try:
        yield staging
        directory.mkdir(exist_ok=True)
        for entry in staging.iterdir():
            target = directory / entry.name
            if target.is_dir() and not target.is_symlink():
                shutil.rmtree(target)
            os.replace(entry, target)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
