"""The named places of the orders: what a panel draws on its map and stages on a click.

A place is a whole command, said without numbers, whose target pose is in the 'map' frame
("reach kitchen": x 3, y 5). Its phrase is the command's first spoken form, so that staging
it is staging what a person would have said.
"""

from __future__ import annotations

from voicectl.shared.messages import Place

from .orders import OrderSet

MAP_FRAME = "map"


def places_of(orders: OrderSet) -> list[Place]:
    """Every place of `orders`, in file order."""
    found = []
    for command in orders.commands:
        if command.slots or not command.expansion.finite or not command.expansion.templates:
            continue
        order = command.to_order({})
        pose = order.target_pose
        if pose is None or pose.frame != MAP_FRAME:
            continue
        phrase = " ".join(str(word) for word in command.expansion.templates[0])
        name = command.case.name if command.case is not None else command.order.name
        title = command.case.description if command.case is not None else order.description
        found.append(
            Place(
                name=name,
                phrase=phrase,
                description=order.description,
                pose=pose,
                language=orders.language,
                title=title,
            )
        )
    return found
