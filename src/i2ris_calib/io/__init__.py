"""Readers and writers of file formats (the stage runners are in ``commands``)."""
