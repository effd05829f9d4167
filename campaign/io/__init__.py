"""How every room touches files and the terminal safely: durable writes (``durable``: atomic replace, fsync), typed
JSON record fields (``json_fields``), spreadsheet-safe CSV cells (``csv_cells``) and terminal-safe text
(``terminal_text``). Imports ``campaign.errors`` only (and the drivers' lazy loader for this door)."""
from drivers import lazy_exports

_HOMES = {                      # module -> the public names it holds
    "csv_cells": ("neutralise", "render_rows", "restore"),
    "durable": ("atomic_write", "create_new", "create_temp", "fsync_dir", "refuse_special", "remove_quietly",
                "stale_temp", "write_all", "write_json"),
    "json_fields": ("RecordError", "check_field", "count_field", "figure_field", "float_list", "float_rows", "get_field",
                    "json_value", "list_field", "mat3_field", "number_field", "object_field", "record_dict",
                    "record_field", "record_map_field", "records_field", "text_field", "vector_field"),
    "quantities": ("CONDITION_SCALE", "FLOOR_FMT", "condition_meaning", "condition_scale", "floor_mm"),
    "terminal_text": ("CleanLogRecords", "clean", "keep_words", "print_notes", "set_width", "stderr_console",
                      "stdout_console"),
}
__all__ = [name for names in _HOMES.values() for name in names]
__getattr__ = lazy_exports(__name__, _HOMES)
