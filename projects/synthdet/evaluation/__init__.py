"""The paper's tables as library functions; the package itself imports nothing.

Each table module builds a JSON-able document (``"format": "synthdet.tableN/1"``) and formats it
as text: ``table1`` (instances per class and area, numpy only), ``table3`` (test metrics per
class, no imports) and ``table4`` (correct and incorrect detections per scan, uses mmdet3d's box
overlaps). ``box_fit`` measures how well the predicted boxes fit the true ones per class
(``tools/test.py --box-fit``), ``false_positives`` what the false positives hit
(``--false-positives``). ``table_files.write_table`` writes a document and its text side
by side.
"""
