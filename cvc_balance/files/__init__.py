"""
Files the commands write: never over their inputs, never half-written under the final name.

Lowest layer beside the physics (standard library only). Public API:
:func:`~cvc_balance.files.outputs.check_output` (before any work) and
:func:`~cvc_balance.files.outputs.replaced_when_done` (a temporary name, renamed at the end).
"""

from cvc_balance.files.outputs import (check_output, moved_into_when_done, OutputError,
                                       replaced_when_done)

__all__ = ['check_output', 'moved_into_when_done', 'OutputError', 'replaced_when_done']
