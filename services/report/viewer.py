"""The report's interactive model: a small canvas viewer inlined in the page (no WebGL, no CDN, offline).

The points travel inside the page as base64: positions quantised to uint16 over the model's bounding box
(6 bytes a point; the step is the box size / 65535, about 3 µm on a 20 cm object), and one or two uint8
RGB colourings: the model's own colours and, where ground truth is known, its per-point error (viridis,
the report's error scale). A ~60-line script projects them with a perspective camera into an ImageData
with a depth buffer (2x2 px splats, nearest wins), so it renders the same in any browser, headless
included. Drag (mouse or touch) turns the model about its centre, the wheel or the +/- buttons zoom,
"error" / "colour" switch the colouring, "reset" returns to the first view.

The exported mesh (``SESSION/mesh.ply``, ``objscan export``) is shown by the same script beside it
(``mesh_viewer_html``): its vertices quantised the same way, its triangles as uint32 indices, one colour a
triangle; each triangle is filled with its colour shaded by how squarely it faces the viewer, back to front
(painter's order), so the closed surface reads as a solid.
"""

from __future__ import annotations

import base64
import html

import numpy as np

MAX_POINTS = 40_000
#: Triangles the mesh viewer is given at most (the export's meshes are about 20,000).
MAX_TRIANGLES = 30_000
CANVAS = (720, 480)

_SCRIPT = r"""
(function(){
const el=document.getElementById('__ID__'),cv=el.querySelector('canvas'),ctx=cv.getContext('2d');
const b64=s=>Uint8Array.from(atob(s),c=>c.charCodeAt(0));
const q=new Uint16Array(b64(el.dataset.xyz).buffer),lo=JSON.parse(el.dataset.lo),hi=JSON.parse(el.dataset.hi);
const n=q.length/3,P=new Float32Array(3*n),C={color:b64(el.dataset.rgb)};  // per point, or per triangle
if(el.dataset.err)C.error=b64(el.dataset.err);
const c0=[0,1,2].map(k=>(lo[k]+hi[k])/2),R=Math.max(1e-3,Math.hypot(hi[0]-lo[0],hi[1]-lo[1],hi[2]-lo[2])/2);
for(let i=0;i<n;i++)for(let k=0;k<3;k++)P[3*i+k]=lo[k]+(hi[k]-lo[k])*q[3*i+k]/65535-c0[k];
const V={az:-0.6,el:0.45,dist:3.2,mode:el.dataset.err?'error':'color'},V0=Object.assign({},V);
const W=cv.width,H=cv.height,img=ctx.createImageData(W,H),Z=new Float32Array(W*H);
const T=el.dataset.tri?new Uint32Array(b64(el.dataset.tri).buffer):null,m=T?T.length/3:0,Nf=new Float32Array(3*m);
for(let t=0;t<m;t++){const a=3*T[3*t],b=3*T[3*t+1],c=3*T[3*t+2],e=[0,1,2].map(k=>P[b+k]-P[a+k]),
  g=[0,1,2].map(k=>P[c+k]-P[a+k]),nx=e[1]*g[2]-e[2]*g[1],ny=e[2]*g[0]-e[0]*g[2],nz=e[0]*g[1]-e[1]*g[0],
  l=Math.hypot(nx,ny,nz)||1;Nf[3*t]=nx/l;Nf[3*t+1]=ny/l;Nf[3*t+2]=nz/l;}
function drawMesh(ca,sa,ce,se,f){
  const D=V.dist*R,S=new Float32Array(3*n),col=C.color,depth=new Float32Array(m),order=new Uint32Array(m);
  for(let i=0;i<n;i++){const x=P[3*i],y=P[3*i+1],z=P[3*i+2],xr=ca*x+sa*y,yr=-sa*x+ca*y,
    w=D-(ce*yr+se*z);S[3*i]=W/2+f*(-xr)/w;S[3*i+1]=H/2-f*(-se*yr+ce*z)/w;S[3*i+2]=w;}
  for(let t=0;t<m;t++){order[t]=t;depth[t]=S[3*T[3*t]+2]+S[3*T[3*t+1]+2]+S[3*T[3*t+2]+2];}
  order.sort((a,b)=>depth[b]-depth[a]);ctx.fillStyle='#fff';ctx.fillRect(0,0,W,H);ctx.lineWidth=0.6;
  for(const t of order){
    if(S[3*T[3*t]+2]<=1e-6||S[3*T[3*t+1]+2]<=1e-6||S[3*T[3*t+2]+2]<=1e-6)continue;
    const nx=Nf[3*t],ny=Nf[3*t+1],nz=Nf[3*t+2],nyr=-sa*nx+ca*ny,k=0.35+0.65*Math.abs(ce*nyr+se*nz);
    const rgb=`rgb(${Math.round(k*col[3*t])},${Math.round(k*col[3*t+1])},${Math.round(k*col[3*t+2])})`;
    ctx.fillStyle=rgb;ctx.strokeStyle=rgb;ctx.beginPath();
    for(let c=0;c<3;c++){const v=3*T[3*t+c];c?ctx.lineTo(S[v],S[v+1]):ctx.moveTo(S[v],S[v+1]);}
    ctx.closePath();ctx.fill();ctx.stroke();}
  el.dataset.drawn=(+(el.dataset.drawn||0)+1);
}
function draw(){
  const ca=Math.cos(V.az),sa=Math.sin(V.az),ce=Math.cos(V.el),se=Math.sin(V.el),f=1.3*Math.min(W,H);
  if(T)return drawMesh(ca,sa,ce,se,f);
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
                *, caption: str = "", seed: int = 0, element_id: str = "model3d") -> str:
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
    return _element(element_id, f"data-xyz=\"{_b64(q)}\" data-lo=\"{list(map(float, lo))}\" "
                                f"data-hi=\"{list(map(float, hi))}\" data-rgb=\"{_b64(rgb)}\"{err_attr}",
                    buttons, caption, "the model")


def mesh_viewer_html(vertices: np.ndarray, triangles: np.ndarray, triangle_rgb: np.ndarray | None = None,
                     *, caption: str = "", element_id: str = "mesh3d") -> str:
    """A closed mesh in the same viewer (``<div id=mesh3d>``): quantised vertices, uint32 triangles, one
    colour per triangle (grey when None). Meshes over ``MAX_TRIANGLES`` should be decimated first."""
    q, lo, hi = quantise(vertices)
    tri = np.ascontiguousarray(triangles, dtype="<u4")
    rgb = np.full((len(tri), 3), 170, np.uint8) if triangle_rgb is None else np.asarray(triangle_rgb, np.uint8)
    buttons = "<button data-zoom='0.8'>+</button><button data-zoom='1.25'>&minus;</button><button>reset</button>"
    return _element(element_id, f"data-xyz=\"{_b64(q)}\" data-lo=\"{list(map(float, lo))}\" "
                                f"data-hi=\"{list(map(float, hi))}\" data-tri=\"{_b64(tri)}\" data-rgb=\"{_b64(rgb)}\"",
                    buttons, caption, "the mesh")


def _element(element_id: str, data: str, buttons: str, caption: str, what: str) -> str:
    w, h = CANVAS
    return (f"<div id=\"{element_id}\" class=\"viewer3d\" {data}>"
            f"<div class='tools'>{buttons}<span>{html.escape(caption)}</span></div>"
            f"<canvas width=\"{w}\" height=\"{h}\" aria-label=\"{what}, drag to turn, wheel to zoom\"></canvas>"
            f"</div><script>{_SCRIPT.replace('__ID__', element_id)}</script>")


CSS = (".viewer3d canvas{border:1px solid #ccc;background:#fff;cursor:grab;touch-action:none;max-width:100%}"
       ".viewer3d .tools{margin:4px 0}.viewer3d button{margin-right:4px}.viewer3d button.on{font-weight:bold}"
       ".viewer3d .tools span{color:#555;margin-left:8px}")
