"""The report's interactive model: a small canvas viewer inlined in the page (no WebGL, no CDN, offline).

The points travel inside the page as base64: positions quantised to uint16 over the model's bounding box
(6 bytes a point; the step is the box size / 65535, about 3 µm on a 20 cm object), and one or two uint8
RGB colourings: the model's own colours and, where ground truth is known, its per-point error (viridis,
the report's error scale). A ~60-line script projects them with a perspective camera into an ImageData
with a depth buffer (2x2 px splats, nearest wins), so it renders the same in any browser, headless
included. Drag (mouse or touch) turns the model about its centre, the wheel or the +/- buttons zoom,
"error" / "colour" switch the colouring, "reset" returns to the first view.
"""

from __future__ import annotations

import base64
import html

import numpy as np

MAX_POINTS = 40_000
CANVAS = (720, 480)

_SCRIPT = r"""
(function(){
const el=document.getElementById('model3d'),cv=el.querySelector('canvas'),ctx=cv.getContext('2d');
const b64=s=>Uint8Array.from(atob(s),c=>c.charCodeAt(0));
const q=new Uint16Array(b64(el.dataset.xyz).buffer),lo=JSON.parse(el.dataset.lo),hi=JSON.parse(el.dataset.hi);
const n=q.length/3,P=new Float32Array(3*n),C={color:b64(el.dataset.rgb)};
if(el.dataset.err)C.error=b64(el.dataset.err);
const c0=[0,1,2].map(k=>(lo[k]+hi[k])/2),R=Math.max(1e-3,Math.hypot(hi[0]-lo[0],hi[1]-lo[1],hi[2]-lo[2])/2);
for(let i=0;i<n;i++)for(let k=0;k<3;k++)P[3*i+k]=lo[k]+(hi[k]-lo[k])*q[3*i+k]/65535-c0[k];
const V={az:-0.6,el:0.45,dist:3.2,mode:el.dataset.err?'error':'color'},V0=Object.assign({},V);
const W=cv.width,H=cv.height,img=ctx.createImageData(W,H),Z=new Float32Array(W*H);
function draw(){
  const ca=Math.cos(V.az),sa=Math.sin(V.az),ce=Math.cos(V.el),se=Math.sin(V.el),f=1.3*Math.min(W,H);
  const col=C[V.mode],d=img.data,D=V.dist*R;d.fill(255);Z.fill(Infinity);
  for(let i=0;i<n;i++){
    const x=P[3*i],y=P[3*i+1],z=P[3*i+2];
    const xr=ca*x+sa*y,yr=-sa*x+ca*y;            // turn about z (up)
    const u=-xr,v=-se*yr+ce*z,w=D-(ce*yr+se*z);  // camera above +y looking at the centre; w = its depth
    if(w<=1e-6)continue;
    const px=Math.round(W/2+f*u/w),py=Math.round(H/2-f*v/w);
    for(let a=0;a<2;a++)for(let b=0;b<2;b++){
      const X=px+a,Y=py+b;if(X<0||Y<0||X>=W||Y>=H)continue;
      const j=Y*W+X;if(w<Z[j]){Z[j]=w;d[4*j]=col[3*i];d[4*j+1]=col[3*i+1];d[4*j+2]=col[3*i+2];d[4*j+3]=255;}
    }
  }
  ctx.putImageData(img,0,0);el.dataset.drawn=(+(el.dataset.drawn||0)+1);
  el.querySelectorAll('button[data-mode]').forEach(b=>b.classList.toggle('on',b.dataset.mode===V.mode));
}
let drag=null;
cv.addEventListener("pointerdown",e=>{drag=[e.clientX,e.clientY];try{cv.setPointerCapture(e.pointerId);}catch(_){}});
cv.addEventListener('pointermove',e=>{if(!drag)return;V.az+=(e.clientX-drag[0])*0.01;
  V.el=Math.max(-1.5,Math.min(1.5,V.el+(e.clientY-drag[1])*0.01));drag=[e.clientX,e.clientY];draw();});
cv.addEventListener('pointerup',()=>{drag=null;});
const zoom=k=>{V.dist=Math.max(1.1,Math.min(20,V.dist*k));draw();};
cv.addEventListener('wheel',e=>{e.preventDefault();zoom(e.deltaY>0?1.15:1/1.15);},{passive:false});
el.querySelectorAll('button').forEach(b=>b.addEventListener('click',()=>{
  if(b.dataset.mode){V.mode=b.dataset.mode;draw();}
  else if(b.dataset.zoom)zoom(+b.dataset.zoom);
  else{Object.assign(V,V0);draw();}}));
draw();
})();
"""


def _b64(a: np.ndarray) -> str:
    return base64.b64encode(np.ascontiguousarray(a).tobytes()).decode("ascii")


def quantise(xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(uint16 (N, 3) little-endian, lo, hi): positions on a 65535-step grid over their bounding box."""
    xyz = np.asarray(xyz, dtype=np.float64)
    lo, hi = xyz.min(axis=0), xyz.max(axis=0)
    span = np.where(hi - lo > 0, hi - lo, 1.0)
    return np.round((xyz - lo) / span * 65535).astype("<u2"), lo, hi


def viewer_html(xyz: np.ndarray, rgb: np.ndarray | None, error_rgb: np.ndarray | None = None,
                *, caption: str = "", seed: int = 0) -> str:
    """The viewer's HTML (a ``<div id=model3d>`` with the data, the canvas, the buttons and the script)."""
    xyz = np.asarray(xyz, dtype=np.float64)
    if len(xyz) > MAX_POINTS:
        idx = np.sort(np.random.default_rng(seed).choice(len(xyz), MAX_POINTS, replace=False))
        xyz = xyz[idx]
        rgb = None if rgb is None else np.asarray(rgb)[idx]
        error_rgb = None if error_rgb is None else np.asarray(error_rgb)[idx]
    q, lo, hi = quantise(xyz)
    rgb = np.full((len(xyz), 3), 170, np.uint8) if rgb is None else np.asarray(rgb, dtype=np.uint8)
    err_attr = f" data-err=\"{_b64(np.asarray(error_rgb, np.uint8))}\"" if error_rgb is not None else ""
    buttons = "<button data-mode='color'>colour</button>"
    if error_rgb is not None:
        buttons += "<button data-mode='error'>error vs ground truth</button>"
    buttons += "<button data-zoom='0.8'>+</button><button data-zoom='1.25'>&minus;</button><button>reset</button>"
    w, h = CANVAS
    return (f"<div id=\"model3d\" data-xyz=\"{_b64(q)}\" data-lo=\"{list(map(float, lo))}\" "
            f"data-hi=\"{list(map(float, hi))}\" data-rgb=\"{_b64(rgb)}\"{err_attr}>"
            f"<div class='tools'>{buttons}<span>{html.escape(caption)}</span></div>"
            f"<canvas width=\"{w}\" height=\"{h}\" aria-label=\"the model, drag to turn, wheel to zoom\"></canvas>"
            f"</div><script>{_SCRIPT}</script>")


CSS = ("#model3d canvas{border:1px solid #ccc;background:#fff;cursor:grab;touch-action:none;max-width:100%}"
       "#model3d .tools{margin:4px 0}#model3d button{margin-right:4px}#model3d button.on{font-weight:bold}"
       "#model3d .tools span{color:#555;margin-left:8px}")
