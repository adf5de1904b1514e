"""Per-kernel device times of SMS rows (BernoulliStage.MIN_LANES from --min-lanes); JSON lines to $OUT."""
import sys, os, json, argparse, time
sys.path.insert(0, os.path.join(os.path.dirname(__file__), '..', 'benchmarks'))
import kernels as K
from grisx.render import sms
p = argparse.ArgumentParser(); p.add_argument('--scenes', default='caustic-slab-plane'); p.add_argument('--rows', required=True)
p.add_argument('--res', nargs=2, type=int, default=[1920, 1080]); p.add_argument('--frames', type=int, default=8); p.add_argument('--device', default='cuda')
p.add_argument('--min-lanes', type=int, nargs='+', default=[32])
p.add_argument('--out', default=os.environ.get('OUT', '/tmp') + '/sms_kern.jsonl')
a = p.parse_args()
for scene in a.scenes.split(','):
    for row in a.rows.split(';'):
        method, *kv = row.split()
        params = {k: int(v) for k, v in (x.split('=', 1) for x in kv)}
        for ml in a.min_lanes:
            sms.BernoulliStage.MIN_LANES = ml
            t0 = time.time()
            r = K.time_method(method, params, argparse.Namespace(scene=scene, device=a.device, res=a.res, frames=a.frames))
            rec = {'scene': scene, 'row': row, 'min_lanes': ml, 'frame_ms': r['frame_ms'], 'phase_ms': r['phase_ms'],
                   'kernel_ms': {k.split(' ')[-1].split('__')[-1]: v for k, v in r['kernel_ms'].items()}, 'wall_s': time.time() - t0}
            open(a.out, 'a').write(json.dumps(rec) + '\n')
            print(scene[-14:], row, 'lanes', ml, 'frame %.2f' % r['frame_ms'], {k: round(v, 2) for k, v in rec['kernel_ms'].items() if v > 0.2}, flush=True)
