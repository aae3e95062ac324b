"""numpydoc, with its docstring template compiled once per build instead of once per docstring.

numpydoc's ``get_doc_object``, which its ``autodoc-process-docstring`` and
``autodoc-process-signature`` handlers call for every documented object (twice per object of
the API pages: its docstring, then its signature), builds a new Jinja environment and compiles
the template ``numpydoc_docstring.rst`` at every call. numpydoc's ``setup`` takes the function
that makes those objects (``get_doc_object_``): this extension, listed in place of ``numpydoc``,
sets numpydoc up with one that compiles the template once per loader, from the loaders numpydoc
uses (the builder's template path, then numpydoc's templates, when a builder is given; numpydoc's
templates alone otherwise), and gives it to numpydoc's Sphinx docstring classes in their
configuration, where they look for it before compiling one. Every docstring is rendered by the
same template as before: the pages are unchanged.
"""

from __future__ import annotations

import os

from jinja2 import FileSystemLoader, Template
from jinja2.sandbox import SandboxedEnvironment
from numpydoc import docscrape, docscrape_sphinx
from numpydoc.numpydoc import setup as numpydoc_setup
from sphinx.jinja2glue import BuiltinTemplateLoader

#: numpydoc's template for a docstring, and the folder it is in.
TEMPLATE = "numpydoc_docstring.rst"
TEMPLATES = os.path.join(os.path.dirname(docscrape_sphinx.__file__), "templates")


class DocObjects:
    """numpydoc's ``get_doc_object`` for the docstrings of one build, its template compiled once per loader."""

    def __init__(self) -> None:
        self.templates: dict[object, Template] = {}  # builder (or None) -> the compiled template

    def template(self, builder) -> Template:
        """The template numpydoc would compile for `builder` (None: numpydoc's own folder), compiled once."""
        if builder not in self.templates:
            if builder is not None:
                loader = BuiltinTemplateLoader()
                loader.init(builder, dirs=[TEMPLATES])
            else:
                loader = FileSystemLoader([TEMPLATES])
            self.templates[builder] = SandboxedEnvironment(loader=loader).get_template(TEMPLATE)
        return self.templates[builder]

    def __call__(self, obj, what=None, doc=None, config=None, builder=None):
        """:func:`numpydoc.docscrape_sphinx.get_doc_object`, with the template compiled once."""
        config = {} if config is None else config
        config["template"] = self.template(builder)
        return docscrape.get_doc_object(obj, what=what, doc=doc, config=config,
                                        class_doc=docscrape_sphinx.SphinxClassDoc,
                                        func_doc=docscrape_sphinx.SphinxFunctionDoc,
                                        obj_doc=docscrape_sphinx.SphinxObjDoc)


def setup(app):
    return numpydoc_setup(app, get_doc_object_=DocObjects())
