"""Stage runners: one module per command (open files, call the stage, write outputs).

``cli`` -> ``commands`` -> the stages; the readers and writers of file formats in
``io`` are used by both.
"""
