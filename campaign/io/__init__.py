"""How every room touches files and the terminal safely: durable writes (``durable``: atomic replace, fsync), typed
JSON record fields (``json_fields``), spreadsheet-safe CSV cells (``csv_cells``) and terminal-safe text
(``terminal_text``). Imports ``campaign.errors`` only."""
