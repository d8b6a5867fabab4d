"""The cab and office screens as web pages (``shoveld cab --web``, ``shoveld office --web``)."""
