"""The one "newest replaces older" mailbox (qrfield.mailbox): what a reader gets, what is counted as
dropped, and its hand-overs between threads. The threaded tests assert outcomes that hold for every
interleaving (each ordering of put and wait ends the same way), so they cannot flake on a loaded
machine; a broken wake-up shows as a thread still blocked after a generous join."""

from __future__ import annotations

import threading

from qrfield.mailbox import Mailbox

JOIN_S = 10.0  # far longer than any hand-over; only reached when a wake-up is lost


def run_thread(target, *args) -> threading.Thread:
    thread = threading.Thread(target=target, args=args, daemon=True)
    thread.start()
    return thread


def test_the_newest_item_replaces_an_unread_one_and_the_drop_is_counted() -> None:
    box: Mailbox[int] = Mailbox()
    assert box.take() is None and not box.full and box.dropped == 0
    assert box.put(1) and box.put(2) and box.put(3)
    assert box.full and box.dropped == 2 and box.puts == 3
    assert box.take() == 3  # the newest; 1 and 2 were never seen
    assert box.take() is None and not box.full
    box.put(4)
    assert box.take() == 4 and box.dropped == 2  # taken in time: not dropped


def test_falsy_items_are_items() -> None:
    box: Mailbox[object] = Mailbox()
    box.put(0)
    box.put(())
    assert box.full and box.dropped == 1 and box.take() == ()
    box.put(None)  # a None item is stored, though take() cannot tell it from "empty"
    assert box.full
    assert box.take() is None and not box.full


def test_put_if_empty_never_replaces_a_newer_item_and_clear_is_not_a_drop() -> None:
    box: Mailbox[str] = Mailbox()
    assert box.put_if_empty("given back")  # nothing newer: it goes in again
    assert box.take() == "given back"
    box.put("newer")
    assert not box.put_if_empty("older") and box.take() == "newer" and box.dropped == 0
    box.put("unwanted")
    assert box.clear() == "unwanted" and box.dropped == 0 and not box.full


def test_wait_gives_the_item_or_none_after_the_timeout() -> None:
    box: Mailbox[int] = Mailbox()
    assert box.wait(0.01) is None
    box.put(7)
    assert box.wait(0.01) == 7 and box.wait(0) is None


def test_wait_wakes_when_another_thread_puts() -> None:
    box: Mailbox[int] = Mailbox()
    got: list[int | None] = []
    consumer = run_thread(lambda: got.append(box.wait()))  # no timeout: only a put ends it
    box.put(5)
    consumer.join(JOIN_S)
    assert not consumer.is_alive() and got == [5]


def test_close_wakes_every_waiter_keeps_the_waiting_item_and_refuses_more() -> None:
    box: Mailbox[int] = Mailbox()
    got: list[int | None] = []
    waiters = [run_thread(lambda: got.append(box.wait())) for _ in range(3)]
    box.close()
    for waiter in waiters:
        waiter.join(JOIN_S)
        assert not waiter.is_alive()
    assert got == [None, None, None] and box.closed
    assert not box.put(1) and box.puts == 0 and not box.full  # discarded once closed

    last: Mailbox[int] = Mailbox()
    last.put(9)
    last.close()
    assert last.wait() == 9 and last.wait() is None  # the frame before the end is not lost


def test_a_producer_one_item_ahead_waits_until_its_item_is_taken() -> None:
    box: Mailbox[int] = Mailbox()
    made: list[int] = []

    def producer() -> None:
        for i in range(5):
            box.wait_taken()
            made.append(i)
            box.put(i)

    thread = run_thread(producer)
    taken = [box.wait(JOIN_S) for _ in range(5)]
    thread.join(JOIN_S)
    assert taken == [0, 1, 2, 3, 4] and box.dropped == 0  # every item, none replaced
    assert box.wait_taken(0)  # empty now
    box.put(1)
    assert not box.wait_taken(0.01)  # still waiting to be taken: timed out
    box.close()
    assert not box.wait_taken()  # closed with the item waiting: returns at once, False


def test_a_fast_producer_and_a_slow_consumer_lose_only_counted_items_in_order() -> None:
    box: Mailbox[int] = Mailbox()
    count = 20_000
    taken: list[int] = []

    def consumer() -> None:
        while True:
            item = box.wait(JOIN_S)
            if item is None:
                return
            taken.append(item)

    thread = run_thread(consumer)
    for i in range(count):
        box.put(i)
    box.close()
    thread.join(JOIN_S)
    assert not thread.is_alive()
    assert taken == sorted(set(taken)), "an older item came after a newer one"
    assert taken[-1] == count - 1  # the newest always arrives
    assert len(taken) + box.dropped == count == box.puts  # each item taken once or counted dropped


def test_an_owner_waits_for_the_box_and_its_own_state_on_one_condition() -> None:
    condition = threading.Condition()
    box: Mailbox[str] = Mailbox(condition)
    state = {"stop": False}
    seen: list[str] = []

    def owner() -> None:
        with condition:  # the box takes the same (reentrant) lock inside: no deadlock
            while True:
                condition.wait_for(lambda: box.full or state["stop"], JOIN_S)
                item = box.take()
                if item is not None:
                    seen.append(item)
                if state["stop"]:
                    return

    thread = run_thread(owner)
    box.put("pose")  # wakes the owner through its own condition
    with condition:
        condition.wait_for(lambda: seen == ["pose"], JOIN_S)
        state["stop"] = True
        condition.notify_all()
    thread.join(JOIN_S)
    assert not thread.is_alive() and seen == ["pose"]


def test_wait_taken_wakes_when_another_thread_takes() -> None:
    box: Mailbox[int] = Mailbox()
    box.put(1)
    result: list[bool] = []
    producer = run_thread(lambda: result.append(box.wait_taken()))
    assert box.wait(JOIN_S) == 1
    producer.join(JOIN_S)
    assert not producer.is_alive() and result == [True]


def test_a_handoff_gives_every_item_in_order_across_threads() -> None:
    """Unlike the mailbox, nothing is dropped: 2000 items put on one thread come out on another,
    all of them, in the order they were put."""
    from qrfield.mailbox import Handoff

    handoff: Handoff[int] = Handoff()
    assert handoff.take() == [] and not handoff.wait(0.01)

    def produce() -> None:
        for k in range(2000):
            handoff.put(k)

    thread = threading.Thread(target=produce, name="test handoff")
    thread.start()
    got: list[int] = []
    while len(got) < 2000:
        assert handoff.wait(10.0)
        got += handoff.take()
    thread.join(10.0)
    assert got == list(range(2000)) and handoff.take() == [] and not thread.is_alive()
