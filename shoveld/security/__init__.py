"""The site network's security: a site CA and per-peer certificates (``pki``), and the
Zenoh access-control lists that let each role do only its job (``acl``)."""
