"""slr_sql: SLR, a Prolog-like language over robot event streams, on a persistent SQLite store.

>>> import slr_sql
>>> with slr_sql.open() as kb:
...     kb.add("obj(cup1, cup, red)^2.0")
...     kb.query("obj(O, cup, C)^T")
[{'O': Atom('cup1'), 'C': Atom('red'), 'T': 2.0}]
"""
from .api import KnowledgeBaseAPI, PendingQueryAPI, ProgramInfo, SolutionsAPI, SubscriptionAPI
from .arguments import check_option_names
from .clocks import Clock, ManualClock, StreamClock, WallClock
from .errors import BufferNotFound, EventRejected, NotAnEvent, SLRBusy, SLRCancelled, SLRError, SLREvaluationError, \
    SLRStatementTimeout, SLRStoreFull, SLRServerUnreachable, SLRStoreGone, SLRSubscriptionInUse, \
    SLRSyntaxError, SLRTimeout, SLRUnavailable
from .kb import KnowledgeBase, open
from .terms import Atom, String, Struct, Var


def connect(url: str, token: str | None = None, **options):
    """A client for the ``slr serve`` at ``url`` with the methods of a local knowledge base
    (``token`` defaults to ``$SLR_TOKEN``; needs ``pip install 'slr_sql[service]'``).

    >>> from slr_sql.service.background import BackgroundServer   # (a server in this program)
    >>> server = BackgroundServer(open(clock=ManualClock(10))).start()
    >>> kb = connect(server.url); kb.add("seen(cup1)^2"); kb.query("seen(X)^T")
    [{'X': Atom('cup1'), 'T': 2.0}]
    >>> kb.close(); server.stop(); server.kb.close()
    >>> connect(server.url, bogus=1)
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: connect has no option 'bogus' (its options: timeout)
    """
    from .service.client import CONNECT_OPTIONS
    from .service.client import connect as _connect  # deferred: `import slr_sql` needs no httpx

    check_option_names("connect", options, CONNECT_OPTIONS)
    return _connect(url, token=token, **options)


__all__ = [
    "open", "connect", "KnowledgeBase", "KnowledgeBaseAPI", "PendingQueryAPI", "SubscriptionAPI",
    "SolutionsAPI", "ProgramInfo", "Clock", "WallClock", "ManualClock", "StreamClock",
    "SLRError", "SLRSyntaxError", "SLREvaluationError", "SLRTimeout", "SLRBusy", "EventRejected",
    "SLRUnavailable", "SLRStoreFull", "SLRStoreGone", "SLRServerUnreachable", "SLRCancelled",
    "SLRStatementTimeout", "SLRSubscriptionInUse", "NotAnEvent", "BufferNotFound",
    "Atom", "String", "Struct", "Var",
]
__version__ = "0.1.0"
