/* Optional C accelerator for the column encoder (slr_sql/encoding.py).
 *
 * The loops that cost most of a vector column's encoding in Python, and nothing else:
 *
 *   number_rows(values)
 *       whether every value is a list or tuple of floats and ints (exact types: what the
 *       general encoder writes as numbers), checked before orjson writes the column;
 *   split_rows(data, count)
 *       the JSON texts of the `count` arrays in `data` (orjson's bytes of a list of lists
 *       of numbers), as encoding._numbers_column_json splits them; None for a row whose text
 *       Python's repr may spell differently (an exponent, "0.0000"), which the caller writes
 *       with the Python encoder; None for the whole column if anything is not digits, signs,
 *       points, commas, brackets or exponents, or the rows do not number `count`;
 *   cons_numbers(values, struct_type, atom_type, cons, nil)
 *       every element of the proper lists of '.'/2 cells in `values`, in one flat list, and
 *       the length of each list (None unless every value is such a list of floats and
 *       integers): the walk of encoding._cons_heads without a Python list per value;
 *   split_flat(data, lengths)
 *       orjson's bytes of that flat list cut back into one JSON array per value, with the
 *       same None rows and None column as split_rows.
 *   event_columns(chunk)
 *       (name, arity, argument columns, starts, ends) of a list of (name, args, start, end)
 *       tuples of one name (an exact str) and one arity (args exact tuples or lists), with
 *       finite float times, start <= end, each -0.0 time given as 0.0: the checks of
 *       store/events.py's _checked_columns in one pass; None at anything else (the Python
 *       checks then decide: they accept more, and say what is wrong);
 *   event_form(events)
 *       "tuples" if every item of the list is a 4-tuple whose args is a tuple, "lists" if
 *       some args are lists instead, None otherwise: kb.py's _event_tuples in one pass.
 *   event_message(row, keys, texts, fallback)
 *       the JSON message of a stored event row (arg1..argN, start, end, arrival, ...) as
 *       slr_sql/viz/channels.py's EventChannel.message writes it, in UTF-8 bytes: `keys` the
 *       N texts before each argument ('{"arg1":', ',"arg2":', ...); an argument that is a
 *       str starting with '[' or '{' (but '{"$atom":') as it is, another str as `texts`
 *       holds it (the cached JSON of atoms), a finite float as repr writes it, an int as
 *       str; anything else (and a str `texts` does not hold) as `fallback(value)` returns
 *       it; the three times as repr(float(t)).
 *   signal_safe(fn, kept)
 *       fn as a function SQLite calls, keeping what a signal handler raised as it was
 *       called (see below); not an encoding loop, and no part of LOOPS_VERSION's contracts:
 *       the store finds it by name (slr_sql/store/connection.py).
 *
 * `data` is orjson's output: its JSON syntax is trusted, every byte is checked. All are
 * pure functions of their arguments (the byte table is constant). The Python versions stay
 * the reference and the fallback: tests/test_speedups.py compares them on random input.
 * The module is built by setup.py when a C compiler is there (optional=True); without it
 * slr_sql runs the same encoding in Python, slower.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <structmember.h>
#include <stddef.h>
#include <string.h>

#ifndef Py_T_OBJECT_EX
#define Py_T_OBJECT_EX T_OBJECT_EX
#endif

/* The offset of a __slots__ attribute in instances of `type`: Struct keeps `name` and `args`
 * in slots, read here without an attribute lookup per cell. -1 with an exception set when
 * the attribute is not an object slot. */
static Py_ssize_t
slot_offset(PyTypeObject *type, const char *attribute)
{
    PyObject *descr = PyObject_GetAttrString((PyObject *)type, attribute);
    Py_ssize_t offset = -1;
    if (descr == NULL)
        return -1;
    /* (a descriptor of another type, borrowed as a class attribute, would give an offset
     * outside the instances of this one) */
    if (Py_IS_TYPE(descr, &PyMemberDescr_Type)
            && PyType_IsSubtype(type, PyDescr_TYPE(descr))) {
        PyMemberDef *member = ((PyMemberDescrObject *)descr)->d_member;
        if (member->type == Py_T_OBJECT_EX || member->type == T_OBJECT)
            offset = member->offset;
    }
    Py_DECREF(descr);
    if (offset < 0)
        PyErr_Format(PyExc_TypeError, "%s.%s is not a slot", type->tp_name, attribute);
    return offset;
}

#define SLOT(object, offset) (*(PyObject **)((char *)(object) + (offset)))

/* 1 if `name` is the atom '.', 0 if not. */
static int
is_cons_name(PyObject *name, PyObject *cons)
{
    if (name == cons)
        return 1;
    return PyUnicode_Check(name) && PyUnicode_CompareWithASCIIString(name, ".") == 0;
}

/* What each byte of orjson's text of numbers in arrays is to the splitters. */
enum {
    INVALID = 0,  /* null, true, a string, an object: the column is not numbers */
    DIGIT,        /* digits and minus signs */
    POINT,        /* '.': where repr's and orjson's texts of small numbers part */
    EXPONENT,     /* 'e', 'E', '+': a number repr may spell differently */
    COMMA,
    OPEN,
    CLOSE,
};
static unsigned char BYTE_KIND[256];

static void
fill_byte_kinds(void)
{
    const char *digits = "0123456789-";
    for (; *digits; digits++)
        BYTE_KIND[(unsigned char)*digits] = DIGIT;
    BYTE_KIND['.'] = POINT;
    BYTE_KIND['e'] = BYTE_KIND['E'] = BYTE_KIND['+'] = EXPONENT;
    BYTE_KIND[','] = COMMA;
    BYTE_KIND['['] = OPEN;
    BYTE_KIND[']'] = CLOSE;
}

/* 1 if the '.' at `at` starts "0.0000" (repr writes such values, below 1e-4, with an
 * exponent): the Python check is the same ("0.0000" anywhere, so 10.00001 too). */
static inline int
small_at(const char *text, Py_ssize_t at, Py_ssize_t size)
{
    return at >= 1 && text[at - 1] == '0' && at + 4 < size && memcmp(text + at + 1, "0000", 4) == 0;
}

/* A str of the ASCII bytes `text[start:end]`, between `open` and `close` when not 0. */
static PyObject *
ascii_text(const char *text, Py_ssize_t start, Py_ssize_t end, char open, char close)
{
    Py_ssize_t extra = open ? 2 : 0;
    PyObject *item = PyUnicode_New(end - start + extra, 127);
    Py_UCS1 *out;
    if (item == NULL)
        return NULL;
    out = PyUnicode_1BYTE_DATA(item);
    if (open)
        *out++ = (Py_UCS1)open;
    memcpy(out, text + start, (size_t)(end - start));
    if (open)
        out[end - start] = (Py_UCS1)close;
    return item;
}

static PyObject *
split_rows(PyObject *Py_UNUSED(module), PyObject *const *args, Py_ssize_t nargs)
{
    const char *text;
    Py_ssize_t size, count, row = 0, at;
    PyObject *rows;
    if (nargs != 2 || !PyBytes_Check(args[0])) {
        PyErr_SetString(PyExc_TypeError, "split_rows(data: bytes, count: int)");
        return NULL;
    }
    count = PyLong_AsSsize_t(args[1]);
    if (count < 0) {
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_ValueError, "split_rows: count must be >= 0");
        return NULL;
    }
    text = PyBytes_AS_STRING(args[0]);
    size = PyBytes_GET_SIZE(args[0]);
    if (size < 2 || text[0] != '[' || text[size - 1] != ']' || count > size)
        Py_RETURN_NONE;
    rows = PyList_New(count);
    if (rows == NULL)
        return NULL;
    at = 1;
    while (at < size - 1) {
        Py_ssize_t start = at, depth = 0;
        int redo = 0;
        PyObject *item;
        if (text[at] != '[' || row >= count)
            goto decline;
        while (at < size - 1) {
            unsigned char kind = BYTE_KIND[(unsigned char)text[at]];
            if (kind == DIGIT || kind == COMMA) {
                at++;
                continue;
            }
            if (kind == POINT)
                redo |= small_at(text, at, size);
            else if (kind == EXPONENT)
                redo = 1;
            else if (kind == OPEN)
                depth++;
            else if (kind == CLOSE) {
                if (--depth == 0) {
                    at++;
                    break;
                }
            }
            else
                goto decline;
            at++;
        }
        if (depth != 0)
            goto decline;
        if (redo) {
            item = Py_None;
            Py_INCREF(item);
        }
        else if ((item = ascii_text(text, start, at, 0, 0)) == NULL) {
            Py_DECREF(rows);
            return NULL;
        }
        PyList_SET_ITEM(rows, row, item);
        row++;
        if (at < size - 1) {
            if (text[at] != ',' || at + 1 == size - 1)
                goto decline;  /* not a comma, or a trailing one */
            at++;
        }
    }
    if (row != count)
        goto decline;
    return rows;
decline:
    /* rows not yet filled are NULL: list_dealloc skips them */
    Py_DECREF(rows);
    Py_RETURN_NONE;
}

/* number_rows(values) -> bool: every value a list or tuple (exactly) whose elements are
 * each a float or an int (exactly: not bool, not an enum, not another subclass). orjson
 * writes more than that as numbers (an Enum member as its value, a list subclass as an
 * array) which the general encoder refuses: a column passes this before orjson sees it. */
static PyObject *
number_rows(PyObject *Py_UNUSED(module), PyObject *values)
{
    Py_ssize_t count, i, k;
    if (!PyList_CheckExact(values)) {
        PyErr_SetString(PyExc_TypeError, "number_rows: a list");
        return NULL;
    }
    count = PyList_GET_SIZE(values);
    for (i = 0; i < count; i++) {
        PyObject *row = PyList_GET_ITEM(values, i), **items;
        Py_ssize_t n;
        if (PyList_CheckExact(row)) {
            items = ((PyListObject *)row)->ob_item;
            n = PyList_GET_SIZE(row);
        }
        else if (PyTuple_CheckExact(row)) {
            items = ((PyTupleObject *)row)->ob_item;
            n = PyTuple_GET_SIZE(row);
        }
        else
            Py_RETURN_FALSE;
        for (k = 0; k < n; k++)
            if (!PyFloat_CheckExact(items[k]) && !PyLong_CheckExact(items[k]))
                Py_RETURN_FALSE;
    }
    Py_RETURN_TRUE;
}

/* cons_numbers(values, struct_type, atom_type, cons, nil) -> (flat, lengths) | None */
static PyObject *
cons_numbers(PyObject *Py_UNUSED(module), PyObject *const *args, Py_ssize_t nargs)
{
    PyObject *values, *cons, *nil, *flat = NULL, *lengths = NULL;
    PyTypeObject *struct_type, *atom_type;
    Py_ssize_t name_at, args_at, count, i;
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError,
                        "cons_numbers(values, struct_type, atom_type, cons, nil)");
        return NULL;
    }
    values = args[0];
    if (!PyList_CheckExact(values) || !PyType_Check(args[1]) || !PyType_Check(args[2])) {
        PyErr_SetString(PyExc_TypeError, "cons_numbers: a list and two types");
        return NULL;
    }
    struct_type = (PyTypeObject *)args[1];
    atom_type = (PyTypeObject *)args[2];
    cons = args[3];
    nil = args[4];
    if ((name_at = slot_offset(struct_type, "name")) < 0
            || (args_at = slot_offset(struct_type, "args")) < 0)
        return NULL;
    count = PyList_GET_SIZE(values);
    if ((flat = PyList_New(0)) == NULL || (lengths = PyList_New(count)) == NULL)
        goto error;
    for (i = 0; i < count; i++) {
        PyObject *cell = PyList_GET_ITEM(values, i), *length;
        Py_ssize_t n = 0;
        while (Py_IS_TYPE(cell, struct_type)) {
            PyObject *name = SLOT(cell, name_at);
            PyObject *cell_args = SLOT(cell, args_at);
            PyObject *head;
            int cons_cell;
            if (name == NULL || cell_args == NULL || !PyTuple_CheckExact(cell_args)
                    || PyTuple_GET_SIZE(cell_args) != 2)
                goto decline;
            cons_cell = is_cons_name(name, cons);
            head = PyTuple_GET_ITEM(cell_args, 0);
            if (!cons_cell || !(PyFloat_CheckExact(head) || PyLong_CheckExact(head)))
                goto decline;
            if (PyList_Append(flat, head) < 0)
                goto error;
            /* a term made cyclic by hand never ends: let signals (Ctrl-C) in now and then */
            if ((++n & 0xFFFF) == 0 && PyErr_CheckSignals() < 0)
                goto error;
            cell = PyTuple_GET_ITEM(cell_args, 1);
        }
        if (!(cell == nil || (Py_IS_TYPE(cell, atom_type)
                              && PyUnicode_CompareWithASCIIString(cell, "[]") == 0)))
            goto decline;
        if ((length = PyLong_FromSsize_t(n)) == NULL)
            goto error;
        PyList_SET_ITEM(lengths, i, length);
    }
    return Py_BuildValue("(NN)", flat, lengths);
decline:
    Py_DECREF(flat);
    Py_DECREF(lengths);
    Py_RETURN_NONE;
error:
    Py_XDECREF(flat);
    Py_XDECREF(lengths);
    return NULL;
}

/* split_flat(data, lengths) -> list | None: orjson's bytes of one flat list of numbers cut
 * into rows of lengths[k] numbers each, every row written as a JSON array. */
static PyObject *
split_flat(PyObject *Py_UNUSED(module), PyObject *const *args, Py_ssize_t nargs)
{
    const char *text;
    Py_ssize_t size, count, row, at = 1;
    PyObject *lengths, *rows;
    if (nargs != 2 || !PyBytes_Check(args[0]) || !PyList_CheckExact(args[1])) {
        PyErr_SetString(PyExc_TypeError, "split_flat(data: bytes, lengths: list)");
        return NULL;
    }
    text = PyBytes_AS_STRING(args[0]);
    size = PyBytes_GET_SIZE(args[0]);
    lengths = args[1];
    count = PyList_GET_SIZE(lengths);
    if (size < 2 || text[0] != '[' || text[size - 1] != ']')
        Py_RETURN_NONE;
    if ((rows = PyList_New(count)) == NULL)
        return NULL;
    for (row = 0; row < count; row++) {
        Py_ssize_t n = PyLong_AsSsize_t(PyList_GET_ITEM(lengths, row)), start, commas;
        int redo = 0;
        PyObject *item;
        if (n < 0) {
            if (!PyErr_Occurred())
                PyErr_SetString(PyExc_ValueError, "split_flat: lengths must be >= 0");
            Py_DECREF(rows);
            return NULL;
        }
        if (n > 0 && at > 1) {  /* the comma before this row's first number */
            if (text[at] != ',')
                goto decline;
            at++;
        }
        start = at;
        /* n numbers: n - 1 commas inside the row, ended by the next comma or the ']' */
        for (commas = n - 1; n > 0;) {
            unsigned char kind = BYTE_KIND[(unsigned char)text[at]];
            if (kind == DIGIT) {
                at++;
            }
            else if (kind == COMMA) {
                if (at == start || text[at - 1] == ',')
                    goto decline;  /* an empty number */
                if (commas-- == 0)
                    break;
                at++;
            }
            else if (kind == POINT) {
                redo |= small_at(text, at, size);
                at++;
            }
            else if (kind == EXPONENT) {
                redo = 1;
                at++;
            }
            else if (at == size - 1 && commas == 0)
                break;  /* the closing ']' of the whole text */
            else
                goto decline;
        }
        if (n > 0 && (at == start || text[at - 1] == ','))
            goto decline;  /* an empty number: the lengths do not fit the text */
        if (redo) {
            item = Py_None;
            Py_INCREF(item);
        }
        else if ((item = ascii_text(text, start, at, '[', ']')) == NULL) {
            Py_DECREF(rows);
            return NULL;
        }
        PyList_SET_ITEM(rows, row, item);
    }
    if (at != size - 1)
        goto decline;  /* numbers left over */
    return rows;
decline:
    Py_DECREF(rows);
    Py_RETURN_NONE;
}

/* A float 0.0 for the -0.0 times event_columns meets (an event time -0.0 is stored as 0.0). */
static PyObject *positive_zero = NULL;

/* event_columns(chunk) -> (name, arity, columns, starts, ends) | None: see the top. No
 * Python code runs inside the loop (exact types only), so the chunk cannot change under it. */
static PyObject *
event_columns(PyObject *Py_UNUSED(module), PyObject *chunk)
{
    Py_ssize_t n, i, k, arity;
    PyObject *first, *name, *args, *columns = NULL, *starts = NULL, *ends = NULL, *result;
    if (!PyList_CheckExact(chunk) || (n = PyList_GET_SIZE(chunk)) == 0)
        Py_RETURN_NONE;
    first = PyList_GET_ITEM(chunk, 0);
    if (!PyTuple_CheckExact(first) || PyTuple_GET_SIZE(first) != 4)
        Py_RETURN_NONE;
    name = PyTuple_GET_ITEM(first, 0);
    args = PyTuple_GET_ITEM(first, 1);
    if (!PyUnicode_CheckExact(name))
        Py_RETURN_NONE;
    if (PyTuple_CheckExact(args))
        arity = PyTuple_GET_SIZE(args);
    else if (PyList_CheckExact(args))
        arity = PyList_GET_SIZE(args);
    else
        Py_RETURN_NONE;
    if ((columns = PyList_New(arity)) == NULL)
        return NULL;
    for (k = 0; k < arity; k++) {
        PyObject *column = PyList_New(n);
        if (column == NULL)
            goto error;
        PyList_SET_ITEM(columns, k, column);
    }
    if ((starts = PyList_New(n)) == NULL || (ends = PyList_New(n)) == NULL)
        goto error;
    for (i = 0; i < n; i++) {
        PyObject *event = PyList_GET_ITEM(chunk, i), *other, *start, *end;
        PyObject **items;
        double s, e;
        if (!PyTuple_CheckExact(event) || PyTuple_GET_SIZE(event) != 4)
            goto decline;
        other = PyTuple_GET_ITEM(event, 0);
        if (other != name && (!PyUnicode_CheckExact(other)
                              || PyUnicode_Compare(other, name) != 0))
            goto decline;  /* (two exact str: no error to clear) */
        args = PyTuple_GET_ITEM(event, 1);
        if (PyTuple_CheckExact(args) && PyTuple_GET_SIZE(args) == arity)
            items = &PyTuple_GET_ITEM(args, 0);
        else if (PyList_CheckExact(args) && PyList_GET_SIZE(args) == arity)
            items = PySequence_Fast_ITEMS(args);
        else
            goto decline;
        start = PyTuple_GET_ITEM(event, 2);
        end = PyTuple_GET_ITEM(event, 3);
        if (!PyFloat_CheckExact(start) || !PyFloat_CheckExact(end))
            goto decline;
        s = PyFloat_AS_DOUBLE(start);
        e = PyFloat_AS_DOUBLE(end);
        if (!(isfinite(s) && isfinite(e) && s <= e))
            goto decline;  /* (false at a NaN, too) */
        if (s == 0.0)
            start = positive_zero;
        if (e == 0.0)
            end = positive_zero;
        for (k = 0; k < arity; k++) {
            Py_INCREF(items[k]);
            PyList_SET_ITEM(PyList_GET_ITEM(columns, k), i, items[k]);
        }
        Py_INCREF(start);
        PyList_SET_ITEM(starts, i, start);
        Py_INCREF(end);
        PyList_SET_ITEM(ends, i, end);
    }
    result = Py_BuildValue("(OnOOO)", name, arity, columns, starts, ends);
    Py_DECREF(columns);
    Py_DECREF(starts);
    Py_DECREF(ends);
    return result;
decline:
    Py_DECREF(columns);  /* (lists free the items set so far; the others are NULL) */
    Py_DECREF(starts);
    Py_DECREF(ends);
    Py_RETURN_NONE;
error:
    Py_XDECREF(columns);
    Py_XDECREF(starts);
    Py_XDECREF(ends);
    return NULL;
}

/* event_form(events) -> "tuples" | "lists" | None: see the top. */
static PyObject *
event_form(PyObject *Py_UNUSED(module), PyObject *events)
{
    Py_ssize_t n, i;
    int lists = 0;
    if (!PyList_CheckExact(events) || (n = PyList_GET_SIZE(events)) == 0)
        Py_RETURN_NONE;
    for (i = 0; i < n; i++) {
        PyObject *event = PyList_GET_ITEM(events, i), *args;
        if (!PyTuple_CheckExact(event) || PyTuple_GET_SIZE(event) != 4)
            Py_RETURN_NONE;
        args = PyTuple_GET_ITEM(event, 1);
        if (PyTuple_CheckExact(args))
            continue;
        if (!PyList_CheckExact(args))
            Py_RETURN_NONE;
        lists = 1;
    }
    return PyUnicode_FromString(lists ? "lists" : "tuples");
}

/* A growing byte buffer (the message being written). */
typedef struct {
    char *data;
    Py_ssize_t size, capacity;
} Buffer;

static int
buffer_add(Buffer *buffer, const char *text, Py_ssize_t size)
{
    if (buffer->size + size > buffer->capacity) {
        Py_ssize_t capacity = (buffer->size + size) * 2 + 64;
        char *data = PyMem_Realloc(buffer->data, capacity);
        if (data == NULL) {
            PyErr_NoMemory();
            return -1;
        }
        buffer->data = data;
        buffer->capacity = capacity;
    }
    memcpy(buffer->data + buffer->size, text, size);
    buffer->size += size;
    return 0;
}

/* The UTF-8 of a str (an exception set when it has none: a lone surrogate). */
static int
buffer_add_str(Buffer *buffer, PyObject *text)
{
    Py_ssize_t size;
    const char *utf8;
    if (!PyUnicode_Check(text)) {
        PyErr_Format(PyExc_TypeError, "a message's text is a str, not %.100s",
                     Py_TYPE(text)->tp_name);
        return -1;
    }
    utf8 = PyUnicode_AsUTF8AndSize(text, &size);
    return utf8 == NULL ? -1 : buffer_add(buffer, utf8, size);
}

/* repr of a float: its shortest text, with ".0" when integral, "inf", "nan". */
static int
buffer_add_double(Buffer *buffer, double value)
{
    char *text = PyOS_double_to_string(value, 'r', 0, Py_DTSF_ADD_DOT_0, NULL);
    int result;
    if (text == NULL)
        return -1;
    result = buffer_add(buffer, text, (Py_ssize_t)strlen(text));
    PyMem_Free(text);
    return result;
}

/* One argument's text (see event_message). */
static int
buffer_add_argument(Buffer *buffer, PyObject *value, PyObject *texts, PyObject *fallback)
{
    PyObject *text;
    int result;
    if (PyUnicode_CheckExact(value)) {
        Py_ssize_t length = PyUnicode_GET_LENGTH(value);
        if (length > 0) {
            Py_UCS4 first = PyUnicode_READ_CHAR(value, 0);
            if (first == '[' || first == '{') {
                static const char atom_head[] = "{\"$atom\":";
                Py_ssize_t k = 0;
                if (first == '{' && length >= 9)
                    while (k < 9 && PyUnicode_READ_CHAR(value, k) == (Py_UCS4)atom_head[k])
                        k++;
                if (k < 9)
                    return buffer_add_str(buffer, value);
            }
        }
        text = PyDict_GetItemWithError(texts, value);   /* borrowed */
        if (text != NULL)
            return buffer_add_str(buffer, text);
        if (PyErr_Occurred())
            return -1;
    }
    else if (PyFloat_CheckExact(value)) {
        double v = PyFloat_AS_DOUBLE(value);
        if (Py_IS_FINITE(v))
            return buffer_add_double(buffer, v);
    }
    else if (PyLong_CheckExact(value)) {
        text = PyObject_Str(value);
        if (text == NULL)
            return -1;
        result = buffer_add_str(buffer, text);
        Py_DECREF(text);
        return result;
    }
    text = PyObject_CallOneArg(fallback, value);
    if (text == NULL)
        return -1;
    result = buffer_add_str(buffer, text);
    Py_DECREF(text);
    return result;
}

static PyObject *
event_message(PyObject *Py_UNUSED(module), PyObject *const *args, Py_ssize_t nargs)
{
    PyObject *row, *keys, *texts, *fallback, *out = NULL;
    Py_ssize_t n, i;
    Buffer buffer = {NULL, 0, 0};
    static const char *const time_keys[3] = {",\"start\":", ",\"end\":", ",\"arrival\":"};
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, "event_message(row, keys, texts, fallback)");
        return NULL;
    }
    row = args[0];
    keys = args[1];
    texts = args[2];
    fallback = args[3];
    if (!PyTuple_Check(row) || !PyTuple_Check(keys) || !PyDict_Check(texts)) {
        PyErr_SetString(PyExc_TypeError,
                        "event_message: row and keys are tuples, texts a dict");
        return NULL;
    }
    n = PyTuple_GET_SIZE(keys);
    if (PyTuple_GET_SIZE(row) < n + 3) {
        PyErr_SetString(PyExc_ValueError, "event_message: the row has no times");
        return NULL;
    }
    for (i = 0; i < n; i++) {
        if (buffer_add_str(&buffer, PyTuple_GET_ITEM(keys, i)) < 0
                || buffer_add_argument(&buffer, PyTuple_GET_ITEM(row, i), texts, fallback) < 0)
            goto done;
    }
    for (i = 0; i < 3; i++) {
        PyObject *t = PyTuple_GET_ITEM(row, n + i);
        double v;
        /* (no argument: the object opens with the start time) */
        const char *key = time_keys[i] + (i == 0 && n == 0 ? 1 : 0);
        if (i == 0 && n == 0 && buffer_add(&buffer, "{", 1) < 0)
            goto done;
        if (buffer_add(&buffer, key, (Py_ssize_t)strlen(key)) < 0)
            goto done;
        if (PyFloat_CheckExact(t))
            v = PyFloat_AS_DOUBLE(t);
        else {
            PyObject *f = PyNumber_Float(t);
            if (f == NULL)
                goto done;
            v = PyFloat_AS_DOUBLE(f);
            Py_DECREF(f);
        }
        if (buffer_add_double(&buffer, v) < 0)
            goto done;
    }
    if (buffer_add(&buffer, "}", 1) < 0)
        goto done;
    out = PyBytes_FromStringAndSize(buffer.data, buffer.size);
done:
    PyMem_Free(buffer.data);
    return out;
}

/* signal_safe(fn, kept): fn as a function SQLite calls (slr_sql/store/connection.py). Python
 * runs a pending signal's handler (a Ctrl-C's KeyboardInterrupt) at the first Python code
 * that runs, most often a function a statement calls row by row, where sqlite3 clears what
 * it raises: the statement fails as if the function had, and the query goes on in the
 * interpreter. The wrapper runs the pending handlers itself before it calls fn, and keeps
 * what they raise -- or what fn raises that is no Exception (KeyboardInterrupt, SystemExit:
 * a signal that came as fn began) -- appended to the list `kept` (when it is empty): the
 * store raises it once the statement ended. The call fails all the same. */
typedef struct {
    PyObject_HEAD
    PyObject *fn;
    PyObject *kept;
    vectorcallfunc vectorcall;
} SignalSafe;

static PyObject *
signal_safe_call(PyObject *op, PyObject *const *args, size_t nargsf, PyObject *kwnames)
{
    SignalSafe *self = (SignalSafe *)op;
    PyObject *type, *value, *traceback;
    if (PyErr_CheckSignals() == 0) {
        PyObject *result = PyObject_Vectorcall(self->fn, args, nargsf, kwnames);
        if (result != NULL || PyErr_ExceptionMatches(PyExc_Exception))
            return result;
    }
    PyErr_Fetch(&type, &value, &traceback);
    PyErr_NormalizeException(&type, &value, &traceback);
    if (value != NULL) {
        if (traceback != NULL)
            PyException_SetTraceback(value, traceback);
        if (PyList_GET_SIZE(self->kept) == 0 && PyList_Append(self->kept, value) < 0)
            PyErr_Clear();
    }
    PyErr_Restore(type, value, traceback);
    return NULL;
}

static int
signal_safe_traverse(SignalSafe *self, visitproc visit, void *arg)
{
    Py_VISIT(self->fn);
    Py_VISIT(self->kept);
    return 0;
}

static int
signal_safe_clear(SignalSafe *self)
{
    Py_CLEAR(self->fn);
    Py_CLEAR(self->kept);
    return 0;
}

static void
signal_safe_dealloc(SignalSafe *self)
{
    PyObject_GC_UnTrack(self);
    signal_safe_clear(self);
    PyObject_GC_Del(self);
}

static PyTypeObject SignalSafeType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "_slr_sql_speedups.SignalSafe",
    .tp_basicsize = sizeof(SignalSafe),
    .tp_dealloc = (destructor)signal_safe_dealloc,
    .tp_vectorcall_offset = offsetof(SignalSafe, vectorcall),
    .tp_call = PyVectorcall_Call,
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC | Py_TPFLAGS_HAVE_VECTORCALL,
    .tp_doc = "A function SQLite calls that keeps what a signal handler raised in it.",
    .tp_traverse = (traverseproc)signal_safe_traverse,
    .tp_clear = (inquiry)signal_safe_clear,
};

static PyObject *
signal_safe(PyObject *module, PyObject *const *args, Py_ssize_t nargs)
{
    SignalSafe *self;
    if (nargs != 2 || !PyCallable_Check(args[0]) || !PyList_CheckExact(args[1])) {
        PyErr_SetString(PyExc_TypeError, "signal_safe(fn, kept): a callable and a list");
        return NULL;
    }
    self = PyObject_GC_New(SignalSafe, &SignalSafeType);
    if (self == NULL)
        return NULL;
    Py_INCREF(args[0]);
    self->fn = args[0];
    Py_INCREF(args[1]);
    self->kept = args[1];
    self->vectorcall = signal_safe_call;
    PyObject_GC_Track(self);
    return (PyObject *)self;
}

static PyMethodDef methods[] = {
    {"number_rows", (PyCFunction)number_rows, METH_O,
     "number_rows(values) -> bool\n\n"
     "Every value a list or tuple of floats and ints (exact types)."},
    {"cons_numbers", (PyCFunction)(void (*)(void))cons_numbers, METH_FASTCALL,
     "cons_numbers(values, struct_type, atom_type, cons, nil) -> (flat, lengths) | None\n\n"
     "All elements of the proper '.'/2 lists of numbers in values, and each list's length."},
    {"split_flat", (PyCFunction)(void (*)(void))split_flat, METH_FASTCALL,
     "split_flat(data, lengths) -> list | None\n\n"
     "orjson's text of a flat list of numbers cut into JSON arrays of the given lengths."},
    {"split_rows", (PyCFunction)(void (*)(void))split_rows, METH_FASTCALL,
     "split_rows(data, count) -> list | None\n\n"
     "The texts of the count JSON arrays of numbers in data (None for rows to write again)."},
    {"event_columns", (PyCFunction)event_columns, METH_O,
     "event_columns(chunk) -> (name, arity, columns, starts, ends) | None\n\n"
     "The argument columns and times of events of one name and arity, checked."},
    {"event_form", (PyCFunction)event_form, METH_O,
     "event_form(events) -> 'tuples' | 'lists' | None\n\n"
     "Whether every event is a 4-tuple with tuple (or list) arguments."},
    {"event_message", (PyCFunction)(void (*)(void))event_message, METH_FASTCALL,
     "event_message(row, keys, texts, fallback) -> bytes\n\n"
     "The JSON message of a stored event row, as EventChannel.message writes it."},
    {"signal_safe", (PyCFunction)(void (*)(void))signal_safe, METH_FASTCALL,
     "signal_safe(fn, kept) -> callable\n\n"
     "fn as a function SQLite calls that keeps what a signal handler raised in it in kept."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_slr_sql_speedups",
    "Optional C loops for slr_sql's column encoder (see slr_sql/encoding.py).", -1, methods,
    NULL, NULL, NULL, NULL,
};

/* What encoding.py expects (LOOPS_VERSION there): raised with every change of these
 * functions' contracts, so that a build older than the source is not used. */
#define LOOPS_VERSION 2

PyMODINIT_FUNC
PyInit__slr_sql_speedups(void)
{
    PyObject *m;
    fill_byte_kinds();
    if (positive_zero == NULL && (positive_zero = PyFloat_FromDouble(0.0)) == NULL)
        return NULL;
    if (PyType_Ready(&SignalSafeType) < 0)
        return NULL;
    m = PyModule_Create(&module);
    if (m != NULL && PyModule_AddIntConstant(m, "LOOPS_VERSION", LOOPS_VERSION) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
