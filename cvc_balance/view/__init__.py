"""
The rerun view of a run (an adapter; the only part that imports rerun).

:mod:`~cvc_balance.view.rerun_log`: ``RunLogger`` (one logger for the live node and
for bags) and ``open_recording``; :mod:`~cvc_balance.view.screenshot`:
``HeadlessViewer`` and ``render`` (rerun's viewer headless, its time cursor set, settled
pictures). Imported on use (rerun is heavy to import).
"""
