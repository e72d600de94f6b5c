"""
Files the commands write: never over their inputs, never half-written under the final name.

Lowest layer beside the physics (standard library only). Public API:
:func:`~cvc_balance.files.outputs.check_output` (before any work),
:func:`~cvc_balance.files.outputs.check_new_output` (recordings: never an existing name),
:func:`~cvc_balance.files.outputs.replaced_when_done` (a temporary name, renamed at the end)
and :func:`~cvc_balance.files.outputs.created_when_done` (the same, under a name not taken).
"""

from cvc_balance.files.outputs import (check_new_output, check_output, created_when_done,
                                       distinct_outputs, moved_into_when_done, OutputError,
                                       replaced_when_done, stale_staging, staging_file)

__all__ = ['check_new_output', 'check_output', 'created_when_done', 'distinct_outputs',
           'moved_into_when_done', 'OutputError', 'replaced_when_done', 'stale_staging',
           'staging_file']
