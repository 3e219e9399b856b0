cd /work/main
for f in 585 525 550; do for s in 0 1 2; do
  .venv/bin/dmtrack run /work/shared/data/7scenes-0000-0699 --feature gray --seed $s --threads 1 --no-progress --no-pointcloud --no-depth-images --intrinsics $f,$f,320,240 --out /tmp/intr/f$f-s$s > /tmp/intr/f$f-s$s.log 2>&1
  echo "$f $s $(grep accuracy /tmp/intr/f$f-s$s.log)"
done; done
