"""Client cases (``client.*``): scenarios the judging server plays for ``manip-conform client``."""
