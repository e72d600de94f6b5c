"""
Output paths of the commands: checked before any work, written under a temporary name.

``replay BAG -o BAG`` used to destroy its input (also through a symlink or a hard link) and
``view BAG -o BAG`` overwrote a bag with an .rrd; a command stopped halfway left a file
that looked complete. So every command checks each output first (its folder exists and
can be written, it is none of the command's inputs: the same file by path, symlink or
hard link, or inside an input directory, or holding one; a file is not asked where a
directory is) and writes it in a staging folder beside it, moved onto the final name only
when the command has finished. Staging folders are named ``NAME.PID.XXXXXXXX.partial``
(visible, the owner's process id in the name): one left by a killed command is removed,
and said, by the next command that writes into that folder once its owner is gone.

Live recordings (``record``, the node's ``record_path``) are written in place instead,
created exclusively (:func:`check_new_output`: an existing name is refused, never
replaced): a killed one keeps every finished chunk under its own name (``cvc-balance
reindex``).
"""

from contextlib import contextmanager
import os
from pathlib import Path
import re
import shutil
import sys
import tempfile

_STAGING = re.compile(r'^(?P<name>.+)\.(?P<pid>\d+)\.[A-Za-z0-9_]{8}\.partial$')


class OutputError(ValueError):
    """An output that must not or cannot be written; ``str()`` says why in one line."""


def check_output(path, inputs=(), directory=False):
    """
    Check that ``path`` may be written by a command reading ``inputs``; raise OutputError.

    ``inputs``: paths (files or directories; None entries skipped). ``directory``: the
    output is a folder (files are written into it; it may exist, and must then be
    writable); else an existing directory is refused (a file is never put in its place).
    Existing outputs are otherwise fine (they are replaced at the end).
    """
    output = Path(path)
    folder = output.parent
    if not folder.is_dir():
        raise OutputError(f'{path}: folder {folder} does not exist')
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputError(f'{path}: folder {folder} cannot be written')
    if output.is_dir():
        if not directory:
            raise OutputError(f'{path}: is a directory; give a file name (a directory is '
                              'never replaced by a file)')
        if not os.access(output, os.W_OK | os.X_OK):
            raise OutputError(f'{path}: directory cannot be written')
    elif directory and output.exists():
        raise OutputError(f'{path}: exists and is not a directory')
    target = output.resolve()
    for source in inputs:
        if source is None or not Path(source).exists():
            continue                    # reading it will say what is wrong
        origin = Path(source).resolve()
        same = target == origin or (output.exists() and os.path.samefile(output, source))
        if same or origin in target.parents or target in origin.parents:
            raise OutputError(f'{path}: is (or holds, or is in) the input {source}; not '
                              'written over it (give another output name)')


def check_new_output(path):
    """
    Check that ``path`` can be created and is not taken; raise OutputError (one line).

    For recordings, which are written in place: an existing file, directory or link of
    that name (a symlink, even a dangling one) is refused, never replaced.
    """
    if os.path.lexists(path):
        raise OutputError(f'{path}: exists; a recording never replaces it (give a name '
                          'not taken)')
    check_output(path, directory=True)


def distinct_outputs(paths):
    """Raise OutputError when two of ``paths`` (None skipped) name the same file."""
    seen = {}
    for path in paths:
        if path is None:
            continue
        key = Path(os.path.abspath(path)).resolve()
        if key in seen:
            raise OutputError(f'{path}: named twice as an output (also as {seen[key]}); give '
                              'each output its own name')
        seen[key] = path


def stale_staging(folder):
    """
    Remove the staging folders (and files) in ``folder`` whose owner process is gone.

    Returns their paths; each is said on stderr, so the user knows what a killed command
    had left.
    """
    removed = []
    try:
        entries = list(Path(folder).iterdir())
    except OSError:
        return removed
    for entry in entries:
        match = _STAGING.match(entry.name)
        if match is None or _alive(int(match['pid'])):
            continue
        try:
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry)
            else:
                entry.unlink()
        except OSError:
            continue
        removed.append(entry)
        print(f'removed {entry}, left by a command that was stopped (process {match["pid"]})',
              file=sys.stderr)
    return removed


def _alive(pid):
    """Whether process ``pid`` exists (one of another user's counts as alive)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


def staging_folder(output):
    """Make and return a staging folder for ``output`` beside it (stale ones cleaned first)."""
    output = Path(output)
    stale_staging(output.parent)
    return Path(tempfile.mkdtemp(prefix=f'{output.name}.{os.getpid()}.', suffix='.partial',
                                 dir=output.parent))


def staging_file(output):
    """Return a new staging file's path beside ``output`` (stale ones cleaned first)."""
    output = Path(output)
    stale_staging(output.parent)
    handle, name = tempfile.mkstemp(prefix=f'{output.name}.{os.getpid()}.', suffix='.partial',
                                    dir=output.parent)
    os.close(handle)
    return Path(name)


@contextmanager
def replaced_when_done(path):
    """
    Yield a temporary path with ``path``'s name; move it onto ``path`` if the block succeeds.

    The temporary lies in a staging folder beside ``path`` (same file system: the move
    is a rename). An existing ``path`` is replaced (a directory only by a directory:
    removed first); on an error the staging folder goes and ``path`` is left as it was.
    """
    output = Path(path)
    staging = staging_folder(output)
    try:
        temporary = staging / output.name
        yield temporary
        if not temporary.exists():
            return                      # nothing was written (the command chose not to)
        if output.is_dir() and not output.is_symlink():
            if not temporary.is_dir():
                raise OutputError(f'{path}: is a directory; not replaced by a file')
            shutil.rmtree(output)
        os.replace(temporary, output)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


class NewOutput:
    """Where :func:`created_when_done` writes (``temporary``) and what it became (``path``)."""

    def __init__(self, temporary):
        """Hold the temporary path; ``path`` is set when the output is in place."""
        self.temporary = temporary
        self.path = None


@contextmanager
def created_when_done(path):
    """
    Yield a :class:`NewOutput`; put its temporary under a name not taken when the block ends.

    ``path`` if free, else ``stem-2.suffix``, ``stem-3.suffix``... (a directory:
    ``name-2``...): claimed without a race (a hard link for a file, an exclusive
    ``mkdir`` for a directory), so nothing existing is ever replaced.
    """
    output = Path(path)
    staging = staging_folder(output)
    try:
        new = NewOutput(staging / output.name)
        yield new
        if not new.temporary.exists():
            return
        for n in range(1, 10_000):
            name = output if n == 1 else output.with_name(
                f'{output.stem}-{n}{output.suffix}' if not new.temporary.is_dir()
                else f'{output.name}-{n}')
            try:
                _claim(new.temporary, name)
            except FileExistsError:
                continue
            new.path = name
            return
        raise OutputError(f'{path}: no free name for the output beside it')
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _claim(temporary, name):
    """Move ``temporary`` to ``name``, which must not exist (FileExistsError if it does)."""
    if temporary.is_dir():
        os.mkdir(name)
        for entry in temporary.iterdir():
            os.replace(entry, name / entry.name)
        return
    os.link(temporary, name)
    os.unlink(temporary)


@contextmanager
def moved_into_when_done(directory):
    """
    Yield a staging folder; move what it holds into ``directory`` if the block succeeds.

    For commands that write several files into a folder the user names (a report): the
    folder is made if absent, files of the same names in it are replaced, others left.
    """
    directory = Path(directory)
    staging = staging_folder(directory)
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
