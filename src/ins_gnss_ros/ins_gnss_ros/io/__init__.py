"""Message I/O: stamps, rclpy message objects, the CDR layout, trial bags (rosbag2 MCAP).

* :mod:`.stamps` -- ``builtin_interfaces/Time`` <-> integer ns <-> float s.
* :mod:`.messages` -- type names and classes, fast default instances (:func:`new`), NaN-aware
  comparison.
* :mod:`.cdr` -- the one CDR layout: message objects (:func:`codec`), numpy columns of many
  payloads (:func:`decode_columns`, :func:`encode_columns`) and the fields of one payload
  (:func:`field_reader`, :func:`field_writer`); padding written as zeros.
* :mod:`.mcap_reader` -- the records of an MCAP file, also of one cut short.
* :mod:`.bag` -- bag folders: :class:`BagWriter`, :func:`read_bag`, :func:`iter_raw`.

Used by the nodes (stamps, :func:`new`), the trial tooling and fault injection; imports
nothing of them.
"""
from .bag import (BagError, BagMessage, BagWriter, bag_message_counts, bag_topics,
                  decode_message, first_line, iter_bag, iter_raw, read_bag, read_raw, resolve,
                  serialize, typestore)
from .cdr import (CdrLayoutError, Codec, codec, column_layout, decode_columns, encode_columns,
                  field_reader, field_writer, payload_stamp_ns, starts_with_header)
from .mcap_reader import RawMessage
from .messages import (MessageTypeError, first_difference, messages_equal, msg_class,
                       msgtype_of, msgtype_of_class, new)
from .stamps import (NS, msg_stamp_ns, ns_to_sec, ns_to_stamp, sec_nanosec, sec_to_ns,
                     sec_to_stamp, sec_to_stamp_ns, set_stamp_ns, set_stamp_sec, stamp_or_arrival,
                     stamp_to_ns, stamp_to_sec)

__all__ = [
    "NS", "BagError", "BagMessage", "BagWriter", "CdrLayoutError", "Codec", "MessageTypeError",
    "RawMessage", "bag_message_counts", "bag_topics", "codec", "column_layout", "decode_columns",
    "decode_message", "encode_columns", "field_reader", "field_writer", "first_difference",
    "first_line", "iter_bag", "iter_raw", "messages_equal", "msg_class", "msg_stamp_ns",
    "msgtype_of", "msgtype_of_class", "new", "ns_to_sec", "ns_to_stamp", "payload_stamp_ns",
    "read_bag", "read_raw", "resolve", "sec_nanosec", "sec_to_ns", "sec_to_stamp",
    "sec_to_stamp_ns", "serialize", "set_stamp_ns", "set_stamp_sec", "stamp_or_arrival",
    "stamp_to_ns",
    "stamp_to_sec", "starts_with_header", "typestore",
]
