"""The peer network as studies: on the twin (``twin``) or as processes (``real``)."""
