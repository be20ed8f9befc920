"""The SLR grammar (``slr.lark``) and the LALR parser generated from it (``slr_parser.py``).

``slr_parser.py`` is lark's standalone parser for ``slr.lark``, generated and committed:

    python -m slr_sql.grammar.generate

(lark's ``python -m lark.tools.standalone -s program -s query -l basic slr.lark``, with the
SHA-256 of the grammar appended as ``GRAMMAR_SHA256``).

It carries its own copy of lark's LALR runtime, so slr_sql needs no ``lark`` at run time.
That matters because the ROS 2 wheels of the ``[ros]`` extra (ros-rosidl-parser) install
``lark-parser`` 0.12, whose files go into the same ``lark/`` directory as lark 1.x: whichever
was installed last wins, and pip does not notice. The generated module is the same parser
whichever wins, or with neither.

Why committed rather than generated when the package is built: an editable install, a
source checkout and every wheel then run the same file, building needs no lark, and a change
of the grammar shows in review with its tables. ``tests/test_parser_standalone.py`` checks that
the committed module was generated from the grammar as it is (its ``GRAMMAR_SHA256``; after
editing the grammar, regenerate), that it parses exactly like a parser the installed lark
builds from the grammar (trees and errors, over the examples, the docs and bad input), and
that slr_sql parses the same with ``lark`` unimportable or replaced.
"""
