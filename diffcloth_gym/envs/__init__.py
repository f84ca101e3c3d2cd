"""Gymnasium environments on the simulator: one file per env, a shared base class
(``base.py``) and the task interface every env implements (``task.py``)."""
