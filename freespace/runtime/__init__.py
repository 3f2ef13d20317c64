"""How a command runs, apart from what it computes: the foundation layer beside :mod:`freespace.errors`.

* :mod:`freespace.runtime.log`: logging set-up and progress bars;
* :mod:`freespace.runtime.parallel`: worker processes that end with the command;
* :mod:`freespace.runtime.shard`: the shard ``K/N`` of a list of frames (work split over machines);
* :mod:`freespace.runtime.signals`: ``SIGTERM`` raised as an exception, signals held back while output is moved
  into place, the extra a missing module needs;

The standard library only (the progress bars import tqdm when shown); never torch.
"""
