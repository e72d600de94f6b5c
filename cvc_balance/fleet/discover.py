"""
The bags under some paths: ``.mcap`` and ``.db3`` files, and rosbag2 directories.

A directory holding ``metadata.yaml`` is one bag (its split files are not bags of their
own); any other directory is searched, files and folders in name order, hidden ones
(a leading ``.``), staging folders of outputs being written (``*.partial``, see
:mod:`cvc_balance.files.outputs`) and symbolic links to directories skipped. Files that
are not regular (a FIFO, a link to a device) are found but never read
(:func:`cvc_balance.fleet.tasks.not_a_bag_file`). A path given that is itself a
bag file or a rosbag2 directory is taken as it is, whatever its suffix.
"""

import os
from pathlib import Path

from cvc_balance.bag.rosbag2 import METADATA

BAG_SUFFIXES = ('.mcap', '.db3')
STAGING_SUFFIX = '.partial'
"""Staging folders of commands writing (or killed while writing): not searched."""


def is_bag_directory(path):
    """Tell whether ``path`` is a rosbag2 directory (it holds metadata.yaml)."""
    return (Path(path) / METADATA).is_file()


def find_bags(paths):
    """
    Return [(bag path, root)] under ``paths`` (files or folders), each bag once, in order.

    ``root`` is the path given that the bag was found under (for the machine's name when
    the bag does not carry one, :func:`cvc_balance.bag.machine.machine_of`). A path that
    does not exist raises FileNotFoundError naming it.
    """
    found, seen = [], set()

    def add(bag, root):
        key = os.path.realpath(bag)
        if key not in seen:
            seen.add(key)
            found.append((Path(bag), Path(root)))

    for given in paths:
        root = Path(given)
        if not root.exists():
            raise FileNotFoundError(f'{given}: no such file or directory')
        if root.is_file() or is_bag_directory(root):
            add(root, root.parent)
            continue
        for directory, folders, files in os.walk(root):
            here = Path(directory)
            folders[:] = [f for f in folders if not f.startswith('.') and
                          not f.endswith(STAGING_SUFFIX)]
            bags = sorted(f for f in folders if is_bag_directory(here / f))
            folders[:] = sorted(f for f in folders if f not in bags)
            # One name order: a folder and a file of one folder never share a name.
            for name in sorted(bags + [name for name in files if not name.startswith('.')
                                       and name.endswith(BAG_SUFFIXES)]):
                add(here / name, root)
    return found
